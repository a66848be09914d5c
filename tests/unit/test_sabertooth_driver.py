"""The real Sabertooth driver talking over a real pty to the firmware-like emulator.

Time is virtual: the test steps `now` by hand and hands it to both sides. The only real
waiting is the bounded `select` loop in `Rig.sync`, which lets the bytes the driver wrote
cross the pty (tens of microseconds) before the emulator is fed.
"""

from __future__ import annotations

import random
import select
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import serial

from firmware_like.pty_link import PtyLink
from firmware_like.sabertooth import SabertoothEmulator, SabertoothPtyDevice
from ramp.errors import ConfigError, DeviceError
from ramp.hal import driver_class
from ramp.hal import sabertooth_codec as codec
from ramp.hal.sabertooth import SabertoothBus, SabertoothMotor

TICK = 0.01
WIRING = {"lf": (128, 1), "lb": (128, 2), "rf": (129, 1), "rb": (129, 2)}


class Rig:
    """Driver + pty + emulator on one virtual time line."""

    def __init__(self, tmp_path: Path, **params: Any) -> None:
        self.link = PtyLink("sabertooth0", tmp_path)
        self.motor_calls: list[tuple[int, int, float]] = []
        self.emu = SabertoothEmulator(
            addresses=(128, 129), on_motor=lambda a, m, d: self.motor_calls.append((a, m, d))
        )
        self.dev = SabertoothPtyDevice(self.link, self.emu)
        self.bus = SabertoothBus("base_motors", {"port": self.link.path, **params})
        self.ch: dict[str, SabertoothMotor] = {
            label: self.bus.channel("motor", f"base.{label}", {"address": a, "motor": m})
            for label, (a, m) in WIRING.items()
        }
        self.now = 0.0
        self.received = 0
        self.raw = bytearray()

    def open(self) -> None:
        self.bus.open(self.now)
        self.sync()

    def sync(self) -> None:
        """Feed the emulator every byte the driver has written, stamped with `now`."""
        want = self.bus.stats["bytes_sent"]
        for _ in range(400):
            data = self.link.read_available()
            if data:
                self.received += len(data)
                self.raw += data
                self.emu.feed(self.now, data)
            if self.received >= want:
                break
            select.select([self.link.fileno()], [], [], 0.005)
        assert self.received == want, "bytes written by the driver never reached the pty"
        self.emu.tick(self.now)

    def step(self, n: int = 1, between: Callable[[], None] | None = None) -> None:
        for _ in range(n):
            self.now = round(self.now + TICK, 9)
            if between is not None:
                between()
            self.bus.tick(self.now, TICK)
            self.sync()

    def motor_packets(self) -> list[tuple[float, int, int, int]]:
        return [p for p in self.emu.packets if p[2] in (0, 1, 4, 5)]

    def close(self) -> None:
        self.bus.close()
        self.link.close()


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[Rig]:
    r = Rig(tmp_path)
    r.open()
    yield r
    r.close()


def window_peaks(packets: list[tuple[float, int, int, int]]) -> int:
    """The most bytes any closed one-second window [t, t+1] carries (4 bytes a packet)."""
    times = sorted(p[0] for p in packets)
    best, j = 0, 0
    for i, t in enumerate(times):
        while j < len(times) and times[j] <= t + 1.0 + 1e-9:
            j += 1
        best = max(best, 4 * (j - i))
    return best


# -- start-up ----------------------------------------------------------------------------------
def test_registry_and_fields() -> None:
    assert driver_class("sabertooth") is SabertoothBus
    assert SabertoothBus.fields["baud"].default == 9600
    assert SabertoothBus.fields["timeout"].default == 0.5
    with pytest.raises(ValueError, match="not a Sabertooth address"):
        SabertoothBus.channel_fields["motor"]["address"].check(140)
    with pytest.raises(ValueError, match="motor number"):
        SabertoothBus.channel_fields["motor"]["motor"].check(3)
    assert "polarity" not in SabertoothBus.channel_fields["motor"]  # not the driver's job


def test_config_errors_name_the_key() -> None:
    with pytest.raises(ConfigError, match=r"buses\.m\.port"):
        SabertoothBus("m", {})
    with pytest.raises(ConfigError, match=r"buses\.m\.baud.*one of 2400"):
        SabertoothBus("m", {"port": "/dev/null", "baud": 4800})
    with pytest.raises(ConfigError, match=r"timeout"):
        SabertoothBus("m", {"port": "/dev/null", "timeout": 20.0})
    bus = SabertoothBus("m", {"port": "/dev/null", "driver": "sabertooth", "sim": True})
    bus.channel("motor", "a.x", {"address": 128, "motor": 1})
    with pytest.raises(ConfigError, match="both use address 128 motor 1"):
        bus.channel("motor", "a.y", {"address": 128, "motor": 1})


def test_startup_programs_timeouts_then_zeros(tmp_path: Path) -> None:
    r = Rig(tmp_path)
    r.ch["lf"].set_duty(0.7)  # before open: must not survive into the new session
    try:
        r.open()
        assert [p[1:] for p in r.emu.packets] == [
            (128, 14, 5), (129, 14, 5),
            (128, 0, 0), (128, 4, 0), (129, 0, 0), (129, 4, 0),
        ]
        assert r.emu.timeout(128) == 0.5 and r.emu.timeout(129) == 0.5
        assert r.ch["lf"].duty == 0.0
        assert r.raw[:4] == bytes([128, 14, 5, (128 + 14 + 5) & 0x7F])
    finally:
        r.close()


def test_autobaud_byte_goes_first_and_timeout_rounds_up(tmp_path: Path) -> None:
    r = Rig(tmp_path, autobaud=True, timeout=0.25)
    try:
        r.open()
        assert r.raw[0] == 0xAA
        assert r.emu.counters["autobaud"] == 1
        assert r.emu.timeout(128) == 0.3  # 0.25 s rounds up to 3 units, never down
    finally:
        r.close()


# -- commands ----------------------------------------------------------------------------------
def test_set_duty_is_on_the_wire_before_the_next_tick(rig: Rig) -> None:
    rig.step(3)
    rig.ch["rb"].set_duty(0.5)
    rig.sync()  # no tick
    assert rig.emu.packets[-1] == (rig.now, 129, 4, 64)
    assert rig.emu.duty(129, 2) == pytest.approx(64 / 127)
    assert rig.motor_calls[-1] == (129, 2, pytest.approx(64 / 127))


def test_duty_sign_only_no_polarity(rig: Rig) -> None:
    rig.ch["lf"].set_duty(-0.5)
    rig.ch["lb"].set_duty(-1.0)
    rig.sync()
    assert [p[1:] for p in list(rig.emu.packets)[-2:]] == [(128, 1, 64), (128, 5, 127)]
    assert rig.emu.duty(128, 1) == pytest.approx(-64 / 127)


def test_out_of_range_duty_is_refused_before_the_wire(rig: Rig) -> None:
    sent = rig.bus.stats["bytes_sent"]
    with pytest.raises(ValueError):
        rig.ch["lf"].set_duty(1.5)
    assert rig.bus.stats["bytes_sent"] == sent


def test_flood_newest_wins_and_budget_holds(rig: Rig) -> None:
    rng = random.Random(7)
    labels = list(WIRING)
    newest: dict[str, float] = {}

    def flood() -> None:
        for _ in range(2000):
            label = rng.choice(labels)
            duty = rng.uniform(-1, 1)
            rig.ch[label].set_duty(duty)
            newest[label] = duty

    rig.step(5, between=flood)  # 10,000 set_duty calls within 5 ticks
    assert rig.bus.stats["max_pending"] <= 4  # one pending value per channel, no backlog
    rig.step(2)
    for label, (a, m) in WIRING.items():
        assert rig.emu.duty(a, m) == pytest.approx(round(abs(newest[label]) * 127) / 127
                                                   * (1 if newest[label] >= 0 else -1))
    rig.step(150)
    assert window_peaks(list(rig.emu.packets)) <= 960
    assert rig.bus.stats["budget_waits"] > 0


def test_sustained_changes_keep_the_bus_busy_but_under_budget(rig: Rig) -> None:
    rng = random.Random(3)

    def change_all() -> None:
        for ch in rig.ch.values():
            ch.set_duty(rng.uniform(-1, 1))

    rig.step(300, between=change_all)
    packets = list(rig.emu.packets)
    assert window_peaks(packets) <= 960
    # every full one-second window after start-up carries at least half of baud/10
    for start in (0.5, 1.0, 1.5, 2.0):
        n = sum(1 for p in packets if start <= p[0] <= start + 1.0)
        assert 4 * n >= 480, (start, 4 * n)
    # and no channel starves: each one got a fresh value at least every 0.1 s
    for a, m in WIRING.values():
        cmds = (0, 1) if m == 1 else (4, 5)
        times = [p[0] for p in packets if p[1] == a and p[2] in cmds and p[0] > 0.5]
        assert max(b - t for t, b in zip(times, times[1:], strict=False)) <= 0.1


def test_refresh_keeps_the_controllers_alive(rig: Rig) -> None:
    rig.ch["lf"].set_duty(0.3)
    rig.ch["rb"].set_duty(-0.6)
    rig.sync()
    rig.step(500)  # 5 s without a single change
    assert rig.emu.counters["timeouts"] == 0
    assert rig.emu.duty(128, 1) == pytest.approx(38 / 127)
    assert rig.emu.duty(129, 2) == pytest.approx(-76 / 127)
    assert rig.bus.stats["refreshes"] > 0
    for a, m in WIRING.values():
        cmds = (0, 1) if m == 1 else (4, 5)
        times = [p[0] for p in rig.emu.packets if p[1] == a and p[2] in cmds]
        gaps = [b - t for t, b in zip(times, times[1:], strict=False)]
        assert max(gaps) <= 0.25  # at least twice per 0.5 s controller timeout
    assert window_peaks(list(rig.emu.packets)) <= 960


def test_controller_stops_the_motors_when_the_supervisor_dies(rig: Rig) -> None:
    rig.ch["lf"].set_duty(1.0)
    rig.ch["rf"].set_duty(-1.0)
    rig.step(10)
    assert rig.emu.duty(128, 1) == 1.0
    last = rig.emu.packets[-1][0]
    # the supervisor is dead: no more driver ticks, only the controller's own clock runs
    for _ in range(60):
        rig.now = round(rig.now + TICK, 9)
        rig.dev.service(rig.now)
    assert rig.emu.duty(128, 1) == 0.0
    assert rig.emu.duty(129, 1) == 0.0
    assert (128, 1, 0.0) in rig.motor_calls and (129, 1, 0.0) in rig.motor_calls
    assert rig.emu.counters["timeouts"] == 2
    assert rig.now - last > 0.5


def test_timeout_is_reprogrammed_after_a_controller_reset(rig: Rig) -> None:
    rig.step(10)
    rig.emu.power_cycle(128)
    assert rig.emu.timeout(128) == 0.0
    rig.step(250)
    assert rig.emu.timeout(128) == 0.5


def test_stop_motors_ignores_the_budget(rig: Rig) -> None:
    for label in WIRING:
        rig.ch[label].set_duty(0.9)
    for _ in range(50):
        rig.ch["lf"].set_duty(0.1)
        rig.ch["lf"].set_duty(0.9)  # drain the bucket
    rig.bus.stop_motors()
    rig.sync()
    assert all(rig.emu.duty(a, m) == 0.0 for a, m in WIRING.values())
    assert all(ch.duty == 0.0 for ch in rig.ch.values())


def test_close_sends_zeros_and_is_idempotent(tmp_path: Path) -> None:
    r = Rig(tmp_path)
    try:
        r.open()
        r.ch["lb"].set_duty(0.5)
        r.sync()
        assert r.emu.duty(128, 2) != 0.0
        r.bus.close()
        r.sync()
        assert r.emu.duty(128, 2) == 0.0
        r.bus.close()
        assert not r.bus.is_open
    finally:
        r.link.close()


# -- failures ----------------------------------------------------------------------------------
def test_unplug_raises_on_next_tick_and_replug_reopens(rig: Rig) -> None:
    rig.ch["lf"].set_duty(0.5)
    rig.step(2)
    rig.link.unplug()
    rig.now += TICK
    with pytest.raises(DeviceError, match="base_motors") as info:
        rig.bus.tick(rig.now, TICK)
    assert info.value.bus == "base_motors"
    rig.ch["lf"].set_duty(0.2)  # a request while broken must not raise into the caller
    with pytest.raises(DeviceError):
        rig.bus.tick(rig.now + TICK, TICK)
    rig.bus.close()
    with pytest.raises(DeviceError, match="sabertooth0") as info:
        rig.bus.open(rig.now)  # still unplugged: the retry fails, naming the port
    assert info.value.bus == "base_motors"
    rig.link.replug()
    rig.received = 0
    rig.emu.packets.clear()
    rig.bus.open(rig.now)
    before = rig.bus.stats["bytes_sent"]
    rig.received = before - 24  # 2 timeouts + 4 zeros were written to the new pty
    rig.sync()
    assert [p[1:] for p in rig.emu.packets] == [
        (128, 14, 5), (129, 14, 5), (128, 0, 0), (128, 4, 0), (129, 0, 0), (129, 4, 0),
    ]
    rig.ch["lf"].set_duty(-0.5)
    rig.sync()
    assert rig.emu.duty(128, 1) == pytest.approx(-64 / 127)


def test_unplug_is_noticed_even_when_nothing_is_due(rig: Rig) -> None:
    rig.step(1)
    rig.link.unplug()
    with pytest.raises(DeviceError, match="vanished"):
        rig.bus.tick(rig.now + 0.001, 0.001)  # too soon for any refresh to be written


def test_open_missing_port_names_bus_and_port(tmp_path: Path) -> None:
    bus = SabertoothBus("ble_motors", {"port": str(tmp_path / "nope")})
    with pytest.raises(DeviceError, match=r"bus ble_motors: cannot open .*nope"):
        bus.open(0.0)
    assert not bus.is_open


def test_exclusive_lock(rig: Rig) -> None:
    other = SabertoothBus("again", {"port": rig.link.path})
    other.channel("motor", "x.y", {"address": 128, "motor": 1})
    with pytest.raises(DeviceError, match="again"):
        other.open(0.0)
    shared = SabertoothBus("shared", {"port": rig.link.path, "exclusive": False})
    shared.open(0.0)
    shared.close()


def test_short_writes_never_split_a_packet(rig: Rig, monkeypatch: pytest.MonkeyPatch) -> None:
    """The OS takes at most 3 bytes per write, every other write nothing at all."""
    real_write = rig.bus._ser.write
    calls = {"n": 0}

    def stingy(data: bytes) -> int:
        calls["n"] += 1
        if calls["n"] % 2 == 0:
            return 0
        return int(real_write(data[:3]))

    monkeypatch.setattr(rig.bus._ser, "write", stingy)
    rng = random.Random(5)

    def change() -> None:
        for _ in range(20):
            rng.choice(list(rig.ch.values())).set_duty(rng.uniform(-1, 1))

    rig.step(100, between=change)
    rig.bus.stop_motors()
    rig.step(5)
    assert rig.bus.stats["short_writes"] > 0
    assert rig.emu.counters["bad_checksum"] == 0
    assert rig.emu.counters["dropped_bytes"] == 0
    packets, rest = codec.decode_all(bytes(rig.raw))
    assert rest == b""
    assert len(packets) == rig.emu.counters["packets"]
    assert all(rig.emu.duty(a, m) == 0.0 for a, m in WIRING.values())


def test_a_stop_finishes_a_half_written_motor_packet_as_speed_zero(
        rig: Rig, monkeypatch: pytest.MonkeyPatch) -> None:
    """The OS took two bytes of a 70 % packet when the motors must stop (a stall, SIGTERM):
    the packet is completed as speed 0, so nothing queued before the stop moves a motor."""
    real_write = rig.bus._ser.write
    allowed: dict[str, int | None] = {"bytes": 2}

    def stingy(data: bytes) -> int:
        n = allowed["bytes"]
        if n is None:
            return int(real_write(data))
        allowed["bytes"] = 0
        return int(real_write(data[:n])) if n else 0

    monkeypatch.setattr(rig.bus._ser, "write", stingy)
    before = len(rig.emu.packets)
    rig.ch["lf"].set_duty(0.7)
    assert rig.bus.stats["short_writes"] == 1
    allowed["bytes"] = None
    rig.bus.stop_motors()
    rig.sync()
    after = [p for p in list(rig.emu.packets)[before:] if p[2] in (0, 1, 4, 5)]
    assert after and all(data == 0 for _, _, _, data in after), after
    assert rig.emu.counters["bad_checksum"] == 0
    assert all(rig.emu.duty(a, m) == 0.0 for a, m in WIRING.values())


def test_full_os_buffer_never_blocks_and_loses_nothing(tmp_path: Path) -> None:
    """Nobody reads the pty for a while at 115200 baud: the driver must hold back, not block,
    and what it wrote must still be whole packets once the reader comes back."""
    r = Rig(tmp_path, baud=115200)
    try:
        r.open()
        rng = random.Random(11)
        stalled_at = None
        last_sent = -1
        for i in range(3000):
            r.now = round(r.now + TICK, 9)
            for _ in range(10):  # more changes than the budget: it is spent every tick
                for ch in r.ch.values():
                    ch.set_duty(rng.uniform(-1, 1))
            r.bus.tick(r.now, TICK)  # nobody drains the master meanwhile
            if r.bus.stats["bytes_sent"] == last_sent:
                stalled_at = i
                break
            last_sent = r.bus.stats["bytes_sent"]
        assert stalled_at is not None, "the pty buffer never filled"
        assert r.bus.stats["bytes_sent"] > 4096
        final = {label: rng.uniform(-1, 1) for label in WIRING}
        for label, duty in final.items():
            r.ch[label].set_duty(duty)
        r.step(5)  # the reader is back: sync drains everything
        r.step(5)
        assert r.emu.counters["bad_checksum"] == 0
        assert r.emu.counters["dropped_bytes"] == 0
        for label, (a, m) in WIRING.items():
            assert r.emu.duty(a, m) == pytest.approx(
                round(abs(final[label]) * 127) / 127 * (1 if final[label] >= 0 else -1)
            )
    finally:
        r.close()


# -- other pyserial URLs -----------------------------------------------------------------------
def test_loop_url_opens_and_echoes_packets() -> None:
    bus = SabertoothBus("loop", {"port": "loop://"})
    ch = bus.channel("motor", "m.a", {"address": 130, "motor": 2})
    bus.open(0.0)
    try:
        ser = bus._ser
        start = ser.read(ser.in_waiting)
        packets, _ = codec.decode_all(start)
        assert packets == [codec.Packet(130, 14, 5), codec.Packet(130, 4, 0)]
        ch.set_duty(-0.25)
        bus.tick(0.01, 0.01)
        assert ser.read(ser.in_waiting) == codec.encode_motor(130, 2, -0.25)
    finally:
        bus.close()


def test_loop_url_never_blocks_when_nobody_reads() -> None:
    bus = SabertoothBus("loop", {"port": "loop://", "baud": 115200})
    ch = bus.channel("motor", "m.a", {"address": 130, "motor": 2})
    bus.open(0.0)
    try:
        for i in range(1, 200):  # ~23 KB of budget, 4 KB of loop buffer
            ch.set_duty((i % 100) / 100)
            bus.tick(i * TICK, TICK)
        assert bus.stats["bytes_sent"] <= bus._ser.buffer_size
    finally:
        bus._ser.reset_input_buffer()
        bus.close()


def test_spy_url_wraps_the_pty(tmp_path: Path) -> None:
    link = PtyLink("st", tmp_path)
    log = tmp_path / "spy.txt"
    emu = SabertoothEmulator()
    dev = SabertoothPtyDevice(link, emu)
    bus = SabertoothBus("spy", {"port": f"spy://{link.path}?file={log}"})
    ch = bus.channel("motor", "m.a", {"address": 129, "motor": 1})
    try:
        bus.open(0.0)
        ch.set_duty(1.0)
        for _ in range(200):
            dev.service(0.0)
            if emu.counters["packets"] >= 3:
                break
            select.select([link.fileno()], [], [], 0.01)
        assert [p[1:] for p in emu.packets] == [(129, 14, 5), (129, 0, 0), (129, 0, 127)]
    finally:
        bus.close()
        link.close()
    assert "TX" in log.read_text()


def test_serial_for_url_is_the_only_way_in(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("serial.Serial used directly")

    seen: list[dict[str, Any]] = []
    real = serial.serial_for_url

    def spy(url: str, **kwargs: Any) -> Any:
        seen.append(kwargs)
        return real(url, **kwargs)

    monkeypatch.setattr(serial, "serial_for_url", spy)
    bus = SabertoothBus("loop", {"port": "loop://"})
    bus.open(0.0)
    bus.close()
    assert seen and seen[0]["timeout"] == 0


def test_a_flood_on_some_channels_cannot_starve_another(rig: Rig) -> None:
    """Three channels change faster than the wire can carry; the fourth, which never
    changes, must still be refreshed in time (it jumps the queue when late)."""
    rng = random.Random(9)
    rig.ch["rb"].set_duty(0.4)

    def flood() -> None:
        for label in ("lf", "lb", "rf"):
            rig.ch[label].set_duty(rng.uniform(-1, 1))

    rig.step(300, between=flood)
    times = [p[0] for p in rig.emu.packets if p[1] == 129 and p[2] in (4, 5)]
    gaps = [b - t for t, b in zip(times, times[1:], strict=False)]
    assert len(times) > 10 and max(gaps) <= 0.25
    assert rig.emu.duty(129, 2) == pytest.approx(51 / 127)
    assert window_peaks(list(rig.emu.packets)) <= 960
