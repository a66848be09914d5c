"""The Sabertooth emulator and the pty link, fed hand-written bytes (not ramp's codec)."""

from __future__ import annotations

import errno
import os
import select
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from firmware_like.pty_link import PtyLink
from firmware_like.sabertooth import SabertoothEmulator, SabertoothPtyDevice


def pkt(address: int, command: int, data: int) -> bytes:
    return bytes([address, command, data, (address + command + data) & 0x7F])


class Recorder:
    def __init__(self) -> None:
        self.calls: list[tuple[int, int, float]] = []

    def __call__(self, address: int, motor: int, duty: float) -> None:
        self.calls.append((address, motor, duty))


def test_motor_commands_move_the_right_motor() -> None:
    rec = Recorder()
    emu = SabertoothEmulator(on_motor=rec)
    emu.feed(0.0, pkt(128, 0, 127) + pkt(128, 5, 64) + pkt(129, 1, 32) + pkt(129, 4, 0))
    assert emu.duty(128, 1) == 1.0
    assert emu.duty(128, 2) == pytest.approx(-64 / 127)
    assert emu.duty(129, 1) == pytest.approx(-32 / 127)
    assert emu.duty(129, 2) == 0.0
    assert rec.calls == [(128, 1, 1.0), (128, 2, -64 / 127), (129, 1, -32 / 127), (129, 2, 0.0)]
    assert [p[1:] for p in emu.packets] == [(128, 0, 127), (128, 5, 64), (129, 1, 32), (129, 4, 0)]


def test_seven_bit_commands() -> None:
    emu = SabertoothEmulator()
    emu.feed(0.0, pkt(128, 6, 0) + pkt(128, 7, 127))
    assert (emu.duty(128, 1), emu.duty(128, 2)) == (-1.0, 1.0)
    emu.feed(0.0, pkt(128, 6, 64))
    assert emu.duty(128, 1) == 0.0


def test_bad_checksum_is_dropped_and_counted() -> None:
    emu = SabertoothEmulator()
    bad = bytes([128, 0, 100, 0])
    emu.feed(0.0, bad + pkt(128, 4, 10))
    assert emu.duty(128, 1) == 0.0
    assert emu.duty(128, 2) == pytest.approx(10 / 127)
    assert emu.counters["bad_checksum"] == 1
    assert emu.counters["packets"] == 1


def test_resync_on_address_byte_mid_packet() -> None:
    emu = SabertoothEmulator()
    # noise, a packet cut after two bytes, then a good one split across two feeds
    emu.feed(0.0, bytes([1, 2]) + bytes([128, 0]) + pkt(129, 0, 50)[:3])
    emu.feed(0.01, pkt(129, 0, 50)[3:])
    assert emu.duty(129, 1) == pytest.approx(50 / 127)
    assert emu.counters["dropped_bytes"] == 4
    assert emu.packets[-1] == (0.01, 129, 0, 50)


def test_foreign_addresses_and_unknown_commands() -> None:
    emu = SabertoothEmulator(addresses=(130,))
    emu.feed(0.0, pkt(128, 0, 100) + pkt(130, 20, 1) + pkt(130, 127, 2))
    assert emu.counters["foreign"] == 1
    assert emu.counters["ignored"] == 2
    assert emu.duty(130, 1) == 0.0


def test_settings_and_mixed_mode_are_recorded() -> None:
    rec = Recorder()
    emu = SabertoothEmulator(on_motor=rec)
    emu.feed(0.0, pkt(128, 2, 30) + pkt(128, 15, 2) + pkt(128, 16, 11) + pkt(128, 17, 0))
    assert emu.controllers[128].settings == {
        "min_voltage": 30, "baud_rate": 2, "ramping": 11, "deadband": 0,
    }
    emu.feed(0.0, pkt(128, 0, 100))
    emu.feed(0.0, pkt(128, 8, 127) + pkt(128, 11, 127))
    assert emu.controllers[128].mixed == {"drive": 1.0, "turn": -1.0}
    assert emu.duty(128, 1) == 0.0  # switching to mixed mode stops the independent motors
    assert (128, 1, 0.0) in rec.calls


def test_serial_timeout_stops_both_motors_and_recovers() -> None:
    rec = Recorder()
    emu = SabertoothEmulator(on_motor=rec)
    emu.feed(0.0, pkt(128, 14, 5) + pkt(128, 0, 127) + pkt(128, 4, 127) + pkt(129, 0, 127))
    assert emu.timeout(128) == 0.5
    emu.tick(0.5)
    assert emu.duty(128, 1) == 1.0
    emu.tick(0.51)
    assert (emu.duty(128, 1), emu.duty(128, 2)) == (0.0, 0.0)
    assert rec.calls[-2:] == [(128, 1, 0.0), (128, 2, 0.0)]
    assert emu.counters["timeouts"] == 1
    assert emu.duty(129, 1) == 1.0  # 129 never had a timeout programmed (off by default)
    emu.tick(5.0)
    assert emu.counters["timeouts"] == 1  # once per silence, not every tick
    emu.feed(5.0, pkt(128, 0, 64))
    assert emu.duty(128, 1) == pytest.approx(64 / 127)
    assert not emu.timed_out(128)


def test_timeout_due_before_a_late_packet_happens_first() -> None:
    rec = Recorder()
    emu = SabertoothEmulator(on_motor=rec)
    emu.feed(0.0, pkt(128, 14, 1) + pkt(128, 0, 127))
    emu.feed(1.0, pkt(128, 4, 10))  # no tick in between: the 0.1 s timeout still fired
    assert emu.counters["timeouts"] == 1
    assert emu.duty(128, 1) == 0.0
    assert emu.duty(128, 2) == pytest.approx(10 / 127)


def test_power_cycle_forgets_the_timeout() -> None:
    emu = SabertoothEmulator()
    emu.feed(0.0, pkt(128, 14, 5) + pkt(128, 0, 127))
    emu.power_cycle(128)
    assert emu.timeout(128) == 0.0
    assert emu.duty(128, 1) == 0.0


def test_paced_bytes_arrive_after_their_wire_time() -> None:
    emu = SabertoothEmulator(baud=9600, paced=True)
    emu.feed(0.0, pkt(128, 0, 127))
    emu.tick(0.004)  # 4 bytes take 4 * 10 / 9600 = 4.1667 ms
    assert emu.duty(128, 1) == 0.0
    assert emu.backlog == 1
    emu.tick(0.0042)
    assert emu.duty(128, 1) == 1.0
    t = emu.packets[-1][0]
    assert t == pytest.approx(40 / 9600)


def test_paced_backlog_builds_when_fed_faster_than_the_wire() -> None:
    emu = SabertoothEmulator(baud=9600, paced=True)
    emu.feed(0.0, pkt(128, 0, 1) * 240)  # one second of wire time at once
    emu.tick(0.5)
    assert 119 <= emu.counters["packets"] <= 120
    emu.tick(1.0 + 1e-9)
    assert emu.counters["packets"] == 240
    assert emu.backlog == 0


def test_on_packet_hook_sees_every_valid_packet() -> None:
    seen: list[tuple[float, int, int, int]] = []
    emu = SabertoothEmulator(on_packet=lambda *p: seen.append(p))
    emu.feed(2.0, pkt(128, 14, 5) + bytes([128, 0, 0, 99]))
    assert seen == [(2.0, 128, 14, 5)]


# -- pty link ----------------------------------------------------------------------------------
def wait_bytes(link: PtyLink, n: int, timeout: float = 2.0) -> bytes:
    """Collect at least n bytes from the master, waiting in a bounded select loop."""
    data = b""
    for _ in range(200):
        data += link.read_available()
        if len(data) >= n:
            return data
        select.select([link.fileno()], [], [], timeout / 200)
    return data


def test_pty_link_carries_raw_bytes_and_survives_replug(tmp_path: Path) -> None:
    link = PtyLink("st", tmp_path)
    try:
        assert os.path.islink(link.path)
        first = os.readlink(link.path)
        assert link.read_available() == b""
        fd = os.open(link.path, os.O_RDWR | os.O_NOCTTY)
        payload = bytes([128, 10, 13, 0x0A, 3, 127])  # \n must not become \r\n
        os.write(fd, payload)
        assert wait_bytes(link, len(payload)) == payload
        link.unplug()
        assert not os.path.exists(link.path)
        with pytest.raises(OSError) as info:
            os.write(fd, b"\x80")
        assert info.value.errno == errno.EIO
        os.close(fd)
        link.replug()
        assert os.path.islink(link.path)
        fd = os.open(link.path, os.O_RDWR | os.O_NOCTTY)
        os.write(fd, b"\x81\x00")
        assert wait_bytes(link, 2) == b"\x81\x00"
        os.close(fd)
        assert link.read_available() == b""  # no EIO once the driver side closed
        assert isinstance(first, str)
    finally:
        link.close()
    assert not os.path.lexists(link.path)


def test_pty_device_feeds_the_emulator(tmp_path: Path) -> None:
    with PtyLink("st", tmp_path) as link:
        emu = SabertoothEmulator()
        dev = SabertoothPtyDevice(link, emu)
        fd = os.open(link.path, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, pkt(129, 4, 100))
            got = 0
            for _ in range(200):
                got += dev.service(1.5)
                if got >= 4:
                    break
                select.select([dev.fileno()], [], [], 0.01)
            assert emu.packets[-1] == (1.5, 129, 4, 100)
        finally:
            os.close(fd)


def test_standalone_tcp_logs_packets() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-u", "-m", "firmware_like.sabertooth", "--tcp", "0",
         "--addresses", "130"],
        stdout=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("sabertooth emulator on socket://127.0.0.1:")
        port = int(line.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
            sock.sendall(pkt(130, 4, 64) + pkt(128, 0, 1))
            logged = proc.stdout.readline().split()
        assert logged[1:5] == ["130", "4", "64", "m2"]
    finally:
        proc.terminate()
        proc.wait(timeout=5)
        if proc.stdout is not None:
            proc.stdout.close()
