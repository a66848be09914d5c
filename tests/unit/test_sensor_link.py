"""The sensor link between the simulator's process and the autonomy's (`ramp.autonomy.hal.
simlink`): its codec with byte strings, its transport over a socketpair (partial reads, a
burst, a peer that vanishes, a peer that sends garbage or never reads), and the `simlink`
drivers against the real IMU and gimbal emulators served by `SensorServer`, both ends on one
scheduler and a virtual clock: samples and positions flow, commands reach the emulators, and
an unplugged board or a lost link is a fault that clears when the board comes back."""

from __future__ import annotations

import json
import math
import socket
from collections.abc import Iterator
from typing import Any

import pytest

from firmware_like.imu import ImuEmulator, ImuTruth
from firmware_like.servo import gimbal_emulator
from ramp.autonomy.config import GimbalConfig, ImuConfig, ServoConfig
from ramp.autonomy.hal.simlink import (
    MAX_FRAME_BYTES,
    SensorLink,
    SimLinkImu,
    SimLinkPanTilt,
    decode,
    encode,
    parse_sample,
)
from ramp.clock import VirtualClock
from ramp.errors import DeviceError, ProtocolError
from ramp.scheduler import Scheduler
from ramp.simulation.arena_process import SensorServer

GIMBAL = GimbalConfig(pan=ServoConfig("pan", 0, -90.0, 90.0, velocity_dps=90.0),
                      tilt=ServoConfig("tilt", 1, -30.0, 45.0, velocity_dps=60.0))


# -- the codec ---------------------------------------------------------------------------------
def test_a_message_is_one_json_line_and_floats_keep_every_bit() -> None:
    x = 0.1 + 0.2
    line = encode("imu", attached=True, s=[[x, 8.0, -1e-300]])
    assert line.endswith(b"\n") and line.count(b"\n") == 1
    used, msg = decode(line)
    assert used == len(line)
    assert msg == {"k": "imu", "attached": True, "s": [[x, 8.0, -1e-300]]}
    assert msg is not None and msg["s"][0][0] == x


def test_a_partial_line_needs_more_bytes_and_two_lines_decode_one_at_a_time() -> None:
    a, b = encode("truth", x=1.5), encode("stop")
    assert decode(a[:-1]) == (0, None)
    assert decode(b"") == (0, None)
    buf = a + b + b"{\"k\":\"tr"
    used, msg = decode(buf)
    assert used == len(a) and msg == {"k": "truth", "x": 1.5}
    used2, msg2 = decode(buf[used:])
    assert msg2 == {"k": "stop"} and decode(buf[used + used2:]) == (0, None)


def test_a_blank_line_is_skipped() -> None:
    assert decode(b"\n" + encode("stop")) == (1, None)
    assert decode(b"  \r\n") == (4, None)


@pytest.mark.parametrize(("data", "what"), [
    (b"not json\n", "not JSON"),
    (b"[1, 2]\n", "not a message"),
    (b"{\"x\": 1}\n", "not a message"),
    (b"{\"k\": 3}\n", "not a message"),
    (b"\xff\xfe\n", "not JSON"),
])
def test_a_line_that_is_not_a_message_is_a_protocol_error(data: bytes, what: str) -> None:
    with pytest.raises(ProtocolError, match=what):
        decode(data)


def test_a_line_longer_than_the_limit_is_refused_before_it_ends() -> None:
    with pytest.raises(ProtocolError, match="longer than"):
        decode(b"x" * (MAX_FRAME_BYTES + 1))
    assert decode(b"x" * MAX_FRAME_BYTES) == (0, None)  # may still end in time


def test_nan_is_never_sent() -> None:
    with pytest.raises(ValueError):
        encode("truth", x=float("nan"))


def test_an_imu_row_is_8_or_11_finite_numbers() -> None:
    s = parse_sample([1.0, 8.0, 0.0, 0.0, -1.0, 0.1, 0.2, 0.3])
    assert s.t == 1.0 and s.accel_g == (0.0, 0.0, -1.0) and s.mag_gauss is None
    assert parse_sample([1.0, 8.0, 0, 0, -1, 0, 0, 0, 0.2, 0.0, 0.4]).mag_gauss == (
        0.2, 0.0, 0.4)
    for bad in ([1.0] * 7, [1.0] * 9, "row", [1.0] * 7 + ["x"], [1.0] * 7 + [1e400]):
        with pytest.raises(ValueError):
            parse_sample(bad)


# -- the transport -----------------------------------------------------------------------------
@pytest.fixture
def pair() -> Iterator[tuple[SensorLink, socket.socket]]:
    """A link on one end of a socketpair; the raw other end."""
    a, b = socket.socketpair()
    link = SensorLink(a)
    yield link, b
    link.close()
    b.close()


def received(link: SensorLink, kind: str) -> list[dict[str, Any]]:
    got: list[dict[str, Any]] = []
    link.on(kind, got.append)
    return got


def test_partial_reads_are_kept_until_the_line_is_whole(
        pair: tuple[SensorLink, socket.socket]) -> None:
    link, peer = pair
    got = received(link, "truth")
    line = encode("truth", x=2.0, y=3.0)
    for i in range(0, len(line), 5):  # five bytes at a time
        peer.sendall(line[i:i + 5])
        link.pump(1.0)
        assert got == ([] if i + 5 < len(line) else [{"k": "truth", "x": 2.0, "y": 3.0}])


def test_a_burst_is_dispatched_in_order(pair: tuple[SensorLink, socket.socket]) -> None:
    link, peer = pair
    got = received(link, "n")
    peer.sendall(b"".join(encode("n", i=i) for i in range(2000)))
    while len(got) < 2000:
        link.pump(1.0)
    assert [m["i"] for m in got] == list(range(2000)) and link.received == 2000


def test_a_handler_that_raises_does_not_end_the_link(
        pair: tuple[SensorLink, socket.socket], caplog: pytest.LogCaptureFixture) -> None:
    link, peer = pair
    got = received(link, "ok")
    link.on("bad", lambda m: [][1])
    peer.sendall(encode("bad") + encode("ok"))
    link.pump(1.0)
    assert link.connected and got == [{"k": "ok"}]
    assert "handling a 'bad' message failed" in caplog.text


def test_a_peer_that_vanishes_closes_the_link_and_says_so(
        pair: tuple[SensorLink, socket.socket]) -> None:
    link, peer = pair
    got = received(link, "truth")
    why: list[str] = []
    link.on_close.append(why.append)
    peer.sendall(encode("truth", x=1.0))
    peer.close()
    link.pump(1.0)
    assert got == [{"k": "truth", "x": 1.0}]  # what came before the end is not lost
    assert link.closed and why == ["the peer closed the link"]
    assert link.send("stop") is False
    link.close()  # twice is fine
    assert why == ["the peer closed the link"]


def test_a_peer_that_sends_garbage_closes_the_link(
        pair: tuple[SensorLink, socket.socket]) -> None:
    link, peer = pair
    why: list[str] = []
    link.on_close.append(why.append)
    peer.sendall(b"garbage\n")
    link.pump(1.0)
    assert link.closed and "not JSON" in why[0]


def test_writing_to_a_vanished_peer_closes_the_link(
        pair: tuple[SensorLink, socket.socket]) -> None:
    link, peer = pair
    peer.close()
    assert link.send("stop") is False and link.closed and "gone" in link.reason


def test_a_peer_that_never_reads_is_given_up_on(
        pair: tuple[SensorLink, socket.socket]) -> None:
    link, _peer = pair
    blob = "x" * 60_000
    for _ in range(200):  # 12 MB: more than any socket buffer and the backlog allowed
        if not link.send("blob", b=blob):
            break
    assert link.closed and "has not read" in link.reason


def test_on_a_scheduler_the_link_reads_between_ticks_and_flushes_a_backlog() -> None:
    clock = VirtualClock()
    sched = Scheduler(clock, 100.0)
    a, b = socket.socketpair()
    left, right = SensorLink(a, sched), SensorLink(b, sched)
    got = received(right, "blob")
    blob = "y" * 60_000
    for i in range(40):  # 2.4 MB: backs up, then drains as the loop runs
        assert left.send("blob", i=i, b=blob)
    sched.run_for(0.5)
    assert [m["i"] for m in got] == list(range(40))
    left.close()
    sched.run_for(0.05)
    assert right.closed


# -- the drivers -------------------------------------------------------------------------------
class Bench:
    """Both ends on one scheduler: the emulators behind `SensorServer` (its tick a task) and
    the drivers on the other end of a socketpair."""

    def __init__(self) -> None:
        self.clock = VirtualClock()
        self.sched = Scheduler(self.clock, 100.0)
        a, b = socket.socketpair()
        self.sim_end = SensorLink(a, self.sched, name="sim end")
        self.link = SensorLink(b, self.sched, name="autonomy end")
        self.emu = ImuEmulator(self.clock, lambda: ImuTruth(), seed=3)
        self.gimbal_emu = gimbal_emulator(self.clock, GIMBAL)
        self.server = SensorServer(self.sim_end, self.emu, self.gimbal_emu)
        self.imu = SimLinkImu(ImuConfig(driver="simlink", data_interval_ms=8), link=self.link)
        self.gimbal = SimLinkPanTilt(GIMBAL, link=self.link)
        self.sched.add_task("server", 100.0, self.server.tick)
        self.sched.add_task("imu", 100.0, self.imu.tick)
        self.sched.add_task("gimbal", 100.0, self.gimbal.tick)

    def run(self, seconds: float) -> None:
        self.sched.run_for(seconds)

    def close(self) -> None:
        self.link.close()
        self.sim_end.close()


@pytest.fixture
def bench() -> Iterator[Bench]:
    b = Bench()
    yield b
    b.close()


def test_imu_samples_cross_the_link_with_their_measured_times(bench: Bench) -> None:
    b = bench
    b.imu.open(b.clock.now())
    b.run(1.0)
    got = b.imu.drain()
    assert b.imu.ready() and 110 <= len(got) <= 126
    stamps = [s.timestamp_ms for s in got]
    assert all(t2 - t1 == 8.0 for t1, t2 in zip(stamps, stamps[1:], strict=False))
    assert all(0.0 < s.t <= b.clock.now() for s in got)
    assert got[-1].specific_force_g[2] == pytest.approx(1.0, abs=0.01)


def test_the_imu_driver_sets_the_interval_and_zeroes_the_gyro_over_the_link(bench: Bench) -> None:
    b = bench
    b.imu.config = ImuConfig(driver="simlink", data_interval_ms=4)
    b.imu.open(0.0)
    b.run(0.5)
    assert b.emu.data_interval_ms == 4
    b.imu.zero_gyro()
    b.run(0.05)
    assert b.emu._zeroing is not None


def test_an_unplugged_imu_is_a_fault_that_clears_when_it_comes_back(bench: Bench) -> None:
    b = bench
    b.imu.open(0.0)
    b.run(0.2)
    assert b.imu.ready()
    b.emu.unplug()
    b.run(0.1)
    assert isinstance(b.imu.fault, DeviceError) and "detached" in str(b.imu.fault)
    b.emu.plug()
    b.run(0.1)
    assert b.imu.ready() and b.imu.drain()


def test_a_lost_link_is_a_fault_of_both_devices_naming_the_link(bench: Bench) -> None:
    b = bench
    b.imu.open(0.0)
    b.gimbal.open(0.0)
    b.gimbal.point(0.0, 0.0)
    b.gimbal.engage()
    b.run(0.2)
    assert b.imu.ready() and b.gimbal.ready()
    b.sim_end.close()  # the simulator's process is gone
    b.run(0.1)
    for device in (b.imu, b.gimbal):
        assert isinstance(device.fault, DeviceError) and not device.ready()
        assert "sensor link lost: the peer closed the link" in str(device.fault)
    assert b.gimbal.angles() == (None, None)


def test_the_gimbal_moves_over_the_link_and_reports_reaching_its_target(bench: Bench) -> None:
    b = bench
    b.gimbal.open(0.0)
    b.gimbal.point(0.0, 0.0)
    b.gimbal.engage()
    b.run(0.1)
    assert b.gimbal.ready() and b.gimbal.reached and b.gimbal.angles() == (0.0, 0.0)
    b.gimbal.point(45.0, -20.0)
    assert not b.gimbal.reached
    b.run(0.3)
    pan, tilt = b.gimbal.angles()
    assert pan is not None and tilt is not None and 0.0 < pan < 45.0 and -20.0 < tilt < 0.0
    b.run(1.0)
    assert b.gimbal.angles() == (45.0, -20.0) and b.gimbal.reached
    assert b.gimbal_emu.angles() == (45.0, -20.0)


def test_a_gimbal_that_comes_back_over_the_link_gets_every_command_again(bench: Bench) -> None:
    b = bench
    b.gimbal.point(10.0, 5.0)
    b.gimbal.engage()
    b.gimbal.open(0.0)
    b.run(0.05)
    assert b.gimbal_emu.pan.engaged and b.gimbal_emu.pan.target_deg == 10.0
    b.gimbal_emu.unplug()
    b.run(0.1)
    assert isinstance(b.gimbal.fault, DeviceError) and "detached" in str(
        b.gimbal.fault)
    assert b.gimbal.pan.position_deg is None
    b.gimbal.tilt.set_target(20.0)  # while away: recorded, not sent
    b.run(0.05)
    assert b.gimbal_emu.tilt.target_deg is None
    b.gimbal_emu.plug()
    b.run(0.1)
    assert b.gimbal.fault is None and b.gimbal.ready()
    assert b.gimbal_emu.tilt.target_deg == 20.0 and b.gimbal_emu.tilt.engaged
    b.gimbal.engage(False)
    b.run(0.05)
    assert not b.gimbal_emu.pan.engaged and b.gimbal.pan.position_deg is None


def test_a_gimbal_that_never_attaches_is_a_fault_after_its_attach_timeout() -> None:
    clock = VirtualClock()
    sched = Scheduler(clock, 100.0)
    a, b = socket.socketpair()
    link = SensorLink(b, sched)
    gimbal = SimLinkPanTilt(GIMBAL, link=link)
    gimbal.open(0.0)
    sched.add_task("gimbal", 100.0, gimbal.tick)
    sched.run_for(GIMBAL.attach_timeout_s + 0.2)
    assert isinstance(gimbal.fault, DeviceError) and "not attached within" in str(gimbal.fault)
    a.close()
    link.close()


def test_the_server_ignores_a_bad_servo_command_and_goes_on(
        bench: Bench, caplog: pytest.LogCaptureFixture) -> None:
    b = bench
    b.gimbal.open(0.0)
    b.run(0.05)
    b.link.send("servo", axis="roll", op="target", v=1.0)
    b.link.send("servo", axis="pan", op="spin", v=1.0)
    b.link.sock.sendall(json.dumps({"k": "servo", "axis": "pan", "op": "target",
                                    "v": 500.0}).encode() + b"\n")
    b.run(0.05)
    assert b.sim_end.connected and b.gimbal_emu.pan.target_deg is None
    assert "expected pan or tilt" in caplog.text and "expected target" in caplog.text


# -- what a broken peer sends (a bad message is refused whole) ---------------------------------
@pytest.mark.parametrize("number", [b"NaN", b"Infinity", b"-Infinity", b"1e400", b"-1e400"])
def test_nan_and_infinity_are_refused_on_the_way_in_as_on_the_way_out(number: bytes) -> None:
    with pytest.raises(ProtocolError, match="sensor link"):
        decode(b'{"k": "truth", "x": ' + number + b"}\n")


def test_a_line_nested_too_deeply_is_a_protocol_error_and_closes_the_link(
        pair: tuple[SensorLink, socket.socket]) -> None:
    deep = b'{"k": "truth", "x": ' + b"[" * 100_000 + b"]" * 100_000 + b"}\n"
    with pytest.raises(ProtocolError, match="nested too deeply"):
        decode(deep)
    link, peer = pair
    why: list[str] = []
    link.on_close.append(why.append)
    peer.sendall(deep + encode("truth", x=1.0))
    for _ in range(10):
        link.pump(0.2)
    assert link.closed and "nested too deeply" in why[0]


def test_decoding_the_first_line_does_not_copy_the_backlog_behind_it() -> None:
    """Copying the whole buffer for each line made a burst cost its length squared (4,000
    messages: 43 ms instead of 3 ms). Checked by what is sliced, not by timing it."""

    class Watched(bytearray):
        def __init__(self, data: bytes) -> None:
            super().__init__(data)
            self.slices: list[object] = []

        def __getitem__(self, key: object) -> object:  # type: ignore[override]
            self.slices.append(key)
            return super().__getitem__(key)  # type: ignore[call-overload]

    line = encode("n", i=1)
    long = Watched(line * (MAX_FRAME_BYTES // len(line)))  # a backlog of a megabyte
    assert decode(long) == (len(line), {"k": "n", "i": 1})
    copied = [k.stop - (k.start or 0) for k in long.slices if isinstance(k, slice)]
    assert copied and max(copied) <= len(line), copied


def test_encoding_a_bad_field_names_the_kind_and_sending_it_names_the_link(
        pair: tuple[SensorLink, socket.socket]) -> None:
    with pytest.raises(ValueError, match="a 'truth' message cannot be sent"):
        encode("truth", x=float("inf"))
    with pytest.raises(ValueError, match="a 'truth' message cannot be sent"):
        encode("truth", x=object())
    link, _peer = pair
    link.name = "sensor link (test)"
    with pytest.raises(ValueError, match=r"sensor link \(test\): a 'imu' message"):
        link.send("imu", s=[[float("nan")]])
    assert link.connected and link.send("stop")


def raw(link: SensorLink, doc: dict[str, Any]) -> None:
    """Send `doc` as one line, bypassing `encode`'s checks (a broken peer)."""
    link.sock.sendall(json.dumps(doc).encode() + b"\n")


ROW = [0.01, 8.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("bad", [
    {"attached": True, "s": [ROW, ROW[:5]]},  # the second row is short
    {"attached": True, "s": [ROW, [*ROW[:7], "x"]]},
    {"attached": True, "s": [ROW, [*ROW[:7], True]]},
    {"attached": "false", "s": [ROW]},
    {"attached": True, "s": "rows"},
])
def test_a_bad_imu_message_changes_nothing(
        bad: dict[str, Any], caplog: pytest.LogCaptureFixture) -> None:
    clock = VirtualClock()
    sched = Scheduler(clock, 100.0)
    a, b = socket.socketpair()
    sim_end, link = SensorLink(a, sched), SensorLink(b, sched, name="autonomy end")
    imu = SimLinkImu(ImuConfig(driver="simlink", data_interval_ms=8), link=link)
    sched.add_task("imu", 100.0, imu.tick)
    imu.open(0.0)
    try:
        for _ in range(3):
            raw(sim_end, {"k": "imu", **bad})
        sched.run_for(0.1)
        assert link.connected and not imu.ready() and imu.drain() == []
        assert "imu: " in caplog.text
    finally:
        link.close()
        sim_end.close()


@pytest.mark.parametrize(("bad", "what"), [
    ({"pos": [10.0], "reached": [[], []]}, '"pos" is not'),  # one position: pan was set
    ({"pos": [10.0, 5.0], "reached": [[10.0], ["x"]]}, "gimbal tilt: target reached"),
    ({"pos": [10.0, float("nan")], "reached": [[10.0], []]}, "NaN in a message"),
    ({"pos": [True, 5.0], "reached": [[], []]}, "gimbal pan: position"),
    ({"pos": [10.0, 5.0], "reached": [[10.0]]}, '"reached" is not'),
])
def test_a_bad_gimbal_message_changes_nothing(
        bad: dict[str, Any], what: str, caplog: pytest.LogCaptureFixture) -> None:
    clock = VirtualClock()
    sched = Scheduler(clock, 100.0)
    a, b = socket.socketpair()
    sim_end, link = SensorLink(a, sched), SensorLink(b, sched, name="autonomy end")
    gimbal = SimLinkPanTilt(GIMBAL, link=link)
    sched.add_task("gimbal", 100.0, gimbal.tick)
    gimbal.point(0.0, 0.0)
    gimbal.engage()
    gimbal.open(0.0)
    try:
        raw(sim_end, {"k": "gimbal", "attached": True, **bad})
        sched.run_for(0.05)
        assert not gimbal.pan.attached and not gimbal.tilt.attached
        assert gimbal.angles() == (None, None) and not gimbal.reached
        assert what in caplog.text or what in link.reason
    finally:
        link.close()
        sim_end.close()


def test_the_server_engages_a_servo_only_for_a_real_true(
        bench: Bench, caplog: pytest.LogCaptureFixture) -> None:
    b = bench
    b.gimbal.open(0.0)
    b.run(0.05)
    b.link.send("servo", axis="pan", op="target", v=10.0)
    for value in ("false", "true", 1, None):
        b.link.send("servo", axis="pan", op="engaged", v=value)
        b.run(0.02)
        assert not b.gimbal_emu.pan.engaged, value
    assert "engaged" in caplog.text and "true or false" in caplog.text
    b.link.send("servo", axis="pan", op="target", v="12")
    b.run(0.02)
    assert b.gimbal_emu.pan.target_deg == 10.0 and "a number" in caplog.text
    b.link.send("servo", axis="pan", op="engaged", v=True)
    b.run(0.02)
    assert b.gimbal_emu.pan.engaged and b.sim_end.connected


class _With:
    """An emulator with some attributes replaced (its class may be compiled, and a compiled
    class's methods cannot be replaced on the instance)."""

    def __init__(self, emulator: Any, **replaced: Any) -> None:
        self._emulator = emulator
        self.__dict__.update(replaced)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._emulator, name)


def test_a_sample_that_cannot_be_sent_loses_only_itself(
        bench: Bench, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    b = bench
    b.imu.open(0.0)
    b.gimbal.open(0.0)
    b.gimbal.point(0.0, 0.0)
    b.gimbal.engage()
    b.run(0.3)
    assert b.imu.ready() and b.gimbal.ready()
    b.imu.drain()
    poll, take = b.emu.poll, b.gimbal_emu.tilt.take_reached
    poisoned: list[float] = []

    def poisoned_poll() -> list[Any]:
        samples = poll()
        if samples and not poisoned:  # one sample goes bad, once
            poisoned.append(samples[0].t)
            samples[0] = samples[0]._replace(t=float("nan"))
        return samples

    monkeypatch.setattr(b.server, "imu", _With(b.emu, poll=poisoned_poll))
    tilt = _With(b.gimbal_emu.tilt, take_reached=lambda: [float("inf"), *take()])
    monkeypatch.setattr(b.server, "gimbal", _With(b.gimbal_emu, tilt=tilt))
    b.gimbal.point(30.0, 0.0)
    b.run(1.0)
    assert b.sim_end.connected and b.gimbal.reached and b.gimbal.angles() == (30.0, 0.0)
    got = b.imu.drain()
    assert len(got) >= 110 and all(math.isfinite(s.t) for s in got)
    assert poisoned[0] not in [s.t for s in got] and b.server.not_finite >= 2
    assert "1 IMU samples not finite" in caplog.text


def test_a_bad_truth_message_leaves_the_mirrored_world_as_it_was() -> None:
    from types import SimpleNamespace

    from ramp.simulation.arena_process import MirroredWorld

    layout = SimpleNamespace(layout=None, start=None, start_pose=None, x=1.0, y=2.0, yaw=0.0,
                             lift_pos=0.0)
    world = MirroredWorld(layout)  # type: ignore[arg-type]
    good = {"t": 5.0, "x": 3.0, "y": 4.0, "yaw": 0.5, "lift": 0.1, "bin_kg": 1.0,
            "delivered_kg": 0.0, "spilled_kg": 0.0, "excavated_kg": 1.0, "collisions": 0,
            "crater_entries": 0}
    for bad in ({**good, "crater_entries": None}, {**good, "lift": "0.2"},
                {**good, "collision_log": [[1.0, "rock"]], "crater_log": [["x", "c"]]}):
        with pytest.raises(ValueError, match="truth: "):
            world.update(bad)
        assert (world.time, world.x, world.y, world.collision_log) == (0.0, 1.0, 2.0, [])
    world.update({**good, "collision_log": [[1.0, "rock"]], "crater_log": []})
    assert (world.time, world.x, world.collision_log) == (5.0, 3.0, [(1.0, "rock")])
