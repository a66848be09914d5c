"""The Hokuyo driver against the emulated UTM-30LX-EW over real loopback TCP, in virtual time.

Both ends run in this process on one `VirtualClock`; they share only the TCP connection.
After every step the rig waits (in wall time, briefly) until the kernel has delivered what
either side sent, so a busy machine slows the test down but cannot change its outcome.
What the driver put on the wire is checked from the emulator's record of command lines.
"""

from __future__ import annotations

import array
import fcntl
import math
import select
import socket
import termios
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from firmware_like.hokuyo import ERROR, TIME_ADJUST, HokuyoEmulator, SensorModel, synthetic_room
from ramp.autonomy.hal.hokuyo import HokuyoLidar, describe_scan, main, parse_address
from ramp.autonomy.hal.lidar import (
    CONFIGURING,
    CONNECTING,
    DISCONNECTED,
    FAULT,
    READY,
    STOPPED,
    STREAMING,
    Scan,
)
from ramp.clock import VirtualClock
from ramp.scheduler import Scheduler

DT = 0.005
HANDSHAKE = ["QT", "VV", "PP", "BM"]


def unsent(fd: int) -> int:
    """Bytes a socket has sent that the peer's kernel has not yet taken (Linux TIOCOUTQ)."""
    if fd < 0:
        return 0
    buf = array.array("i", [0])
    try:
        fcntl.ioctl(fd, termios.TIOCOUTQ, buf)
    except OSError:
        return 0
    return buf[0]


class Rig:
    """Emulator and driver on one virtual clock; `step` moves time and lets bytes land."""

    def __init__(self, emu: dict[str, Any] | None = None, **lidar: Any) -> None:
        self.clock = VirtualClock(1000.0)
        self.emu = HokuyoEmulator(self.clock, **(emu or {}))
        self.lidar = HokuyoLidar(self.emu.url, clock=self.clock, **lidar)
        self.scans: list[Scan] = []
        self.lidar.add_listener(self.scans.append)

    @property
    def wire(self) -> list[str]:
        return self.emu.sensor.received

    def settle(self) -> None:
        now = self.clock.now()
        for _ in range(500):
            self.emu.service(now)
            self.lidar.on_readable()
            fds = [self.lidar.fileno(), self.emu.client_fileno]
            if not any(unsent(fd) for fd in fds):
                self.emu.service(now)
                self.lidar.on_readable()
                if not any(unsent(fd) for fd in fds):
                    return
            select.select([fd for fd in fds if fd >= 0], [], [], 0.002)

    def step(self, dt: float = DT) -> None:
        self.clock.advance(dt)
        self.emu.service()
        self.lidar.tick(self.clock.now(), dt)
        self.settle()

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / DT)):
            self.step()

    def run_until(self, cond: Callable[[], bool], limit: float = 5.0) -> float:
        """Step until `cond()`; returns the virtual seconds it took (fails past `limit`)."""
        t0 = self.clock.now()
        while not cond():
            assert self.clock.now() - t0 < limit, (
                f"not reached in {limit} s: state {self.lidar.state}, fault {self.lidar.fault!r}"
                f", wire {self.wire}")
            self.step()
        return self.clock.now() - t0

    def start(self) -> None:
        self.lidar.start()
        self.settle()

    def close(self) -> None:
        self.lidar.stop()
        self.emu.close()


@pytest.fixture
def rig() -> Iterator[Rig]:
    r = Rig()
    yield r
    r.close()


def ready(r: Rig) -> Rig:
    r.start()
    r.run_until(lambda: r.lidar.state == READY)
    return r


# -- start-up -----------------------------------------------------------------------------------
def test_start_up_sends_qt_vv_pp_bm_and_keeps_the_sensors_geometry(rig: Rig) -> None:
    assert rig.lidar.state == STOPPED and rig.lidar.latest is None
    rig.start()
    assert rig.run_until(lambda: rig.lidar.state == READY) < 0.05
    assert rig.wire == HANDSHAKE
    assert rig.lidar.fault == ""
    v, p, g = rig.lidar.version, rig.lidar.params, rig.lidar.geometry
    assert v is not None and "UTM-30LX-EW" in v.product
    assert p is not None and (p.amin, p.amax, p.afrt, p.ares, p.dmin_mm, p.dmax_mm) == (
        0, 1080, 540, 1440, 23, 60000)
    assert g is not None and g.scan_period_s == pytest.approx(0.025)
    assert rig.emu.sensor.laser_on


def test_gd_serves_one_scan_in_metres_stamped_by_both_clocks(rig: Rig) -> None:
    ready(rig)
    asked_at = rig.clock.now()
    assert rig.lidar.request_scan()
    assert rig.lidar.request_scan()  # one is already on its way: not asked twice
    took = rig.run_until(lambda: rig.lidar.latest is not None, limit=0.2)
    assert rig.wire == [*HANDSHAKE, "GD0000108001"]
    assert took <= 0.025 + 0.019 + DT  # the next whole scan, at most one period away
    scan = rig.lidar.latest
    assert scan is not None and scan.seq == 1 and rig.scans == [scan]
    room = np.asarray(synthetic_room()(0.0)) / 1000.0
    assert scan.ranges.shape == (1081,) and np.allclose(scan.ranges, room)
    assert scan.valid.all()
    assert math.degrees(scan.angles[0]) == pytest.approx(-135.0)
    assert scan.angles[540] == 0.0 and scan.range_at(0.0) == pytest.approx(4.0)
    assert asked_at < scan.received_at <= rig.clock.now()
    # Stamped at step 0; complete 18.75 ms later; received at the first step after that.
    late_ms = rig.emu.sensor.timestamp(scan.received_at) - scan.sensor_ms
    assert 18.75 <= late_ms <= 18.75 + DT * 1000
    assert scan.sensor_time == pytest.approx(scan.sensor_ms / 1000.0)
    assert "1081 valid" in describe_scan(scan) and "ahead 4.000 m" in describe_scan(scan)


def test_readings_below_dmin_or_above_dmax_are_nan_not_ranges() -> None:
    ranges = np.full(1081, 2500)
    ranges[100:110] = 1  # "no object in range"
    ranges[200] = 22  # the last error code
    ranges[300] = 60001  # beyond DMAX
    r = Rig(emu={"range_source": lambda t: ranges})
    try:
        ready(r)
        r.lidar.request_scan()
        r.run_until(lambda: r.lidar.latest is not None)
        scan = r.lidar.latest
        assert scan is not None
        bad = np.zeros(1081, dtype=bool)
        bad[[*range(100, 110), 200, 300]] = True
        assert np.array_equal(~scan.valid, bad) and np.isnan(scan.ranges[bad]).all()
        assert scan.raw[100] == 1 and scan.raw[200] == 22  # the codes stay readable
        assert np.allclose(scan.ranges[~bad], 2.5)
        assert len(scan.points()) == 1081 - 12
    finally:
        r.close()


def test_a_partial_clustered_scan_is_asked_for_and_its_bearings_are_cluster_centres() -> None:
    r = Rig(first_step=180, last_step=900, cluster=3)
    try:
        ready(r)
        r.lidar.request_scan()
        r.run_until(lambda: r.lidar.latest is not None)
        assert r.wire[-1] == "GD0180090003"
        scan = r.lidar.latest
        assert scan is not None and len(scan.ranges) == 241 and scan.steps[0] == 180
        assert math.degrees(scan.angles[0]) == pytest.approx((181 - 540) * 0.25)
        assert math.degrees(scan.angles[-1]) == pytest.approx((900 - 540) * 0.25)
    finally:
        r.close()


# -- streaming ----------------------------------------------------------------------------------
def test_md_streams_a_scan_every_25_ms_of_clock_time(rig: Rig) -> None:
    ready(rig)
    rig.lidar.start_stream()
    rig.run_until(lambda: rig.lidar.state == STREAMING)
    assert rig.wire[-1] == "MD0000108001000"
    rig.run(1.0)
    assert 39 <= len(rig.scans) <= 41
    stamps = np.array([s.sensor_time for s in rig.scans])
    assert np.allclose(np.diff(stamps), 0.025)
    assert [s.seq for s in rig.scans] == list(range(1, len(rig.scans) + 1))
    assert not rig.lidar.request_scan()  # streaming: read `latest` instead


def test_qt_while_a_scan_is_in_flight_drains_it_up_to_the_qt_echo(rig: Rig) -> None:
    ready(rig)
    rig.lidar.start_stream()
    rig.run(0.2)
    before = len(rig.scans)
    # A scan leaves the sensor, and the driver sends QT before reading it.
    rig.clock.advance(0.025)
    rig.emu.service()
    assert unsent(rig.emu.client_fileno) or select.select([rig.lidar.fileno()], [], [], 1)[0]
    rig.lidar.stop_stream()
    assert rig.lidar.state == CONFIGURING
    rig.settle()
    rig.run_until(lambda: rig.lidar.state == READY)
    assert rig.wire[-3:] == ["MD0000108001000", "QT", "BM"]
    assert len(rig.scans) == before + 1  # the in-flight scan was good and kept
    assert rig.lidar.stats["unexpected"] == 0 and rig.lidar.stats["bad_replies"] == 0
    rig.run(0.2)
    assert len(rig.scans) == before + 1  # nothing after the QT echo
    assert rig.lidar.request_scan()
    rig.run_until(lambda: len(rig.scans) == before + 2)
    assert rig.wire[-1] == "GD0000108001"


def test_stop_stream_while_the_md_is_still_unanswered_ends_the_stream(rig: Rig) -> None:
    ready(rig)
    rig.lidar.start_stream()  # MD on the wire, its acknowledgement not read yet
    rig.lidar.stop_stream()
    rig.run_until(lambda: rig.lidar.state == READY and rig.lidar.pending_commands == 0)
    assert rig.wire[-3:] == ["MD0000108001000", "QT", "BM"]
    seen = len(rig.scans)
    rig.run(0.2)
    assert len(rig.scans) == seen and rig.lidar.state == READY


def test_a_host_name_that_does_not_resolve_is_retried_with_a_backoff(
        monkeypatch: pytest.MonkeyPatch) -> None:
    def no_dns(*args: object, **kwargs: object) -> None:  # no resolver: same on any machine
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "getaddrinfo", no_dns)
    clock = VirtualClock()
    lidar = HokuyoLidar("no-such-lidar.invalid:10940", clock=clock, backoff_min=0.5)
    try:
        lidar.start()
        assert lidar.state == DISCONNECTED and "cannot resolve the host" in lidar.fault
        assert lidar.fault.endswith("retrying in 0.5 s")
        clock.advance(0.6)
        lidar.tick(clock.now(), 0.6)
        assert lidar.fault.endswith("retrying in 1 s")
    finally:
        lidar.stop()


def test_stream_asked_for_before_the_link_is_up_starts_once_ready() -> None:
    r = Rig(stream=True)
    try:
        r.start()
        r.run_until(lambda: r.lidar.state == STREAMING)
        assert r.wire == [*HANDSHAKE, "MD0000108001000"]
    finally:
        r.close()


def test_the_timestamp_unwraps_across_the_sensors_24_bit_wrap() -> None:
    r = Rig(emu={"timestamp_offset_ms": (1 << 24) - 500}, stream=True)
    try:
        r.start()
        r.run(1.0)
        raw = [s.sensor_ms for s in r.scans]
        assert any(b < a for a, b in zip(raw, raw[1:], strict=False))  # it did wrap
        assert np.allclose(np.diff([s.sensor_time for s in r.scans]), 0.025)
    finally:
        r.close()


# -- losing the link ----------------------------------------------------------------------------
def test_a_dropped_connection_reconnects_after_a_backoff_and_streams_again() -> None:
    r = Rig(stream=True, backoff_min=0.5)
    try:
        r.start()
        r.run(0.3)
        r.emu.drop_connection()
        r.step()
        assert r.lidar.state == DISCONNECTED
        assert "connection closed by the sensor; retrying in 0.5 s" in r.lidar.fault
        seen = len(r.scans)
        r.run(0.45)
        assert r.emu.sensor.counters.connections == 1 and len(r.scans) == seen
        took = r.run_until(lambda: r.lidar.state == STREAMING, limit=1.0)
        assert took <= 0.1 and r.lidar.fault == ""
        assert r.wire[-5:] == [*HANDSHAKE, "MD0000108001000"]
        r.run(0.3)
        assert len(r.scans) > seen + 5 and r.lidar.stats["disconnects"] == 1
    finally:
        r.close()


def test_back_off_doubles_while_nothing_listens_then_resets_on_success() -> None:
    r = Rig(backoff_min=0.25, backoff_max=2.0)
    try:
        port = r.emu.address[1]
        r.emu.close()  # nothing listens on the port any more
        r.lidar.start()
        attempts = [0.0]
        last = r.lidar.stats["connects"]
        while r.clock.now() < 1000.0 + 8.0:
            r.step(0.01)
            if r.lidar.stats["connects"] != last:
                last = r.lidar.stats["connects"]
                attempts.append(r.clock.now() - 1000.0)
        gaps = np.diff(attempts)  # counted from each failure, seen at most a step late
        assert list(gaps[:5]) == pytest.approx([0.25, 0.5, 1.0, 2.0, 2.0], abs=0.021)
        assert "ECONNREFUSED" in r.lidar.fault and r.lidar.state == DISCONNECTED
        r.emu = HokuyoEmulator(r.clock, port=port)
        r.run_until(lambda: r.lidar.state == READY, limit=3.0)
        r.emu.drop_connection()
        r.step()
        assert r.lidar.fault.endswith("retrying in 0.25 s")
    finally:
        r.close()


def test_connecting_to_a_closed_port_returns_at_once() -> None:
    clock = VirtualClock()
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]  # bound, not listening: refused
        lidar = HokuyoLidar(f"127.0.0.1:{port}", clock=clock)
        try:
            t0 = time.perf_counter()
            lidar.start()
            for _ in range(10):
                clock.advance(DT)
                lidar.tick(clock.now(), DT)
            spent = time.perf_counter() - t0
            assert lidar.state == DISCONNECTED and "ECONNREFUSED" in lidar.fault
        finally:
            lidar.stop()
    assert spent < 0.5  # eleven calls, each returning at once


def test_connecting_to_a_listener_that_never_answers_never_blocks_the_caller() -> None:
    """A full accept backlog drops SYNs, so a blocking connect() would hang for seconds."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(0)
        fillers = []
        for _ in range(8):  # fill the backlog; later SYNs are dropped, connects hang
            s = socket.socket()
            s.setblocking(False)
            s.connect_ex(server.getsockname())
            fillers.append(s)
        time.sleep(0.05)  # test set-up on the wall clock: let the kernel settle the handshakes
        clock = VirtualClock()
        lidar = HokuyoLidar(f"127.0.0.1:{server.getsockname()[1]}", clock=clock,
                            connect_timeout=1.0)
        costs = []
        try:
            t = time.perf_counter()
            lidar.start()
            costs.append(time.perf_counter() - t)
            assert lidar.state == CONNECTING
            while clock.now() < 1.3:  # the timeout at 1.0 s, the retry due at 1.5 s
                clock.advance(0.01)
                t = time.perf_counter()
                lidar.tick(clock.now(), 0.01)
                costs.append(time.perf_counter() - t)
        finally:
            lidar.stop()
            for s in fillers:
                s.close()
    assert max(costs) < 0.5  # each call returns at once (a hung connect takes >= 1 s)
    assert sum(costs) < 2.0
    assert "connect timed out after 1.0 s" in lidar.fault


def test_a_silent_sensor_is_noticed_within_the_reply_timeout() -> None:
    r = Rig(reply_timeout=0.3)
    try:
        ready(r)
        r.emu.sensor.muted = True
        asked = r.clock.now()
        r.lidar.request_scan()
        r.run_until(lambda: r.lidar.state == DISCONNECTED, limit=1.0)
        assert r.clock.now() - asked == pytest.approx(0.325, abs=2 * DT)
        assert "no reply to GD within 0.33 s" in r.lidar.fault
        r.emu.sensor.muted = False
        r.run_until(lambda: r.lidar.state == READY, limit=2.0)
    finally:
        r.close()


def test_a_stalled_stream_is_noticed_and_the_link_reset() -> None:
    r = Rig(stream=True, stream_timeout=0.2)
    try:
        r.start()
        r.run_until(lambda: r.lidar.state == STREAMING)
        r.run(0.1)
        r.emu.sensor.muted = True  # the sensor stops sending, the link stays up
        r.run_until(lambda: r.lidar.state == DISCONNECTED, limit=1.0)
        assert "no scan for 0.20 s while streaming" in r.lidar.fault
    finally:
        r.close()


# -- sensor faults --------------------------------------------------------------------------------
def test_a_hardware_error_during_a_stream_is_a_fault_not_bad_ranges() -> None:
    r = Rig(stream=True, fault_retry=1.0)
    try:
        r.start()
        r.run(0.3)
        good = r.lidar.latest
        seen = len(r.scans)
        r.emu.inject_error(52)
        r.settle()
        assert r.lidar.state == FAULT
        assert "sensor hardware error 52 on MD stream: hardware trouble" in r.lidar.fault
        assert "127.0.0.1" in r.lidar.fault
        r.run(0.9)
        assert r.lidar.latest is good and len(r.scans) == seen
        assert not r.lidar.request_scan()
        r.run(0.2)  # the retry: QT answered 0L while the sensor is in error
        assert r.lidar.state == FAULT and "QT answered 0L" in r.lidar.fault
        assert r.wire[-1] == "QT" and r.emu.sensor.state == ERROR
        r.emu.clear_error()
        r.run_until(lambda: r.lidar.state == STREAMING, limit=1.5)
        assert r.lidar.fault == "" and r.wire[-5:] == [*HANDSHAKE, "MD0000108001000"]
        r.run(0.2)
        assert len(r.scans) > seen
    finally:
        r.close()


def test_a_hardware_error_answering_gd_is_a_fault(rig: Rig) -> None:
    ready(rig)
    rig.emu.sensor.inject_error(75)
    assert rig.lidar.request_scan()
    rig.run_until(lambda: rig.lidar.state == FAULT)
    assert "sensor hardware error 75 on GD" in rig.lidar.fault
    assert rig.lidar.latest is None
    rig.run(2.1)  # retried: BM 01 (laser malfunction) is still a fault
    assert rig.lidar.state == FAULT


def test_a_laser_that_will_not_switch_on_is_a_fault() -> None:
    r = Rig()
    try:
        r.emu.sensor.laser_fault = True
        r.start()
        r.run_until(lambda: r.lidar.state == FAULT)
        assert "BM answered 01: unable to control the laser" in r.lidar.fault
        assert r.wire == HANDSHAKE
        r.emu.sensor.laser_fault = False
        r.run_until(lambda: r.lidar.state == READY, limit=3.0)
        assert r.wire == HANDSHAKE * 2  # retried from the top after `fault_retry`
    finally:
        r.close()


def test_a_corrupted_scan_is_dropped_and_the_stream_goes_on() -> None:
    r = Rig(stream=True)
    try:
        r.start()
        r.run(0.2)
        r.emu.sensor.corrupt_next = 1
        r.run(0.2)
        assert r.lidar.stats["bad_replies"] == 1 and r.lidar.state == STREAMING
        room = np.asarray(synthetic_room()(0.0)) / 1000.0
        assert all(np.allclose(s.ranges, room) for s in r.scans)
        assert r.emu.sensor.counters.scans_sent == len(r.scans) + 1
    finally:
        r.close()


def test_a_sensor_of_another_model_is_refused() -> None:
    r = Rig(emu={"model": SensorModel(model="URG-04LX", amin=44, amax=725, afrt=384,
                                      ares=1024, dmin=20, dmax=5600, scan_rpm=600)})
    try:
        r.start()
        r.run_until(lambda: r.lidar.state == FAULT)
        assert "the sensor is a 'URG-04LX', expected a UTM-30LX" in r.lidar.fault
        assert r.wire == ["QT", "VV", "PP"]  # the laser was never switched on
    finally:
        r.close()


def test_steps_outside_the_sensors_range_are_refused_at_pp() -> None:
    r = Rig(last_step=1200)
    try:
        r.start()
        r.run_until(lambda: r.lidar.state == FAULT)
        assert "steps 0..1200 are outside the sensor's 0..1080" in r.lidar.fault
    finally:
        r.close()


# -- odd sensor states ----------------------------------------------------------------------------
def test_a_sensor_left_in_time_adjust_mode_is_brought_back_with_tm2() -> None:
    r = Rig()
    try:
        r.emu.sensor.feed(r.clock.now(), b"TM0\n")
        r.emu.sensor.take_output()
        assert r.emu.sensor.state == TIME_ADJUST
        ready(r)
        assert r.wire == ["TM0", "QT", "TM2", "QT", "VV", "PP", "BM"]
    finally:
        r.close()


def test_a_stream_left_running_by_a_previous_client_is_drained_up_to_the_qt_echo() -> None:
    r = Rig()
    try:
        r.emu.sensor.feed(r.clock.now(), b"MD0000108001000\n")  # before we ever connected
        r.lidar.start()
        r.clock.advance(0.06)  # two scans are sent before our QT is read
        r.settle()
        r.run_until(lambda: r.lidar.state == READY)
        assert r.wire == ["MD0000108001000", *HANDSHAKE]
        assert r.lidar.stats["drained"] >= 2 and r.scans == []
        assert r.lidar.stats["unexpected"] == 0 and r.lidar.stats["bad_replies"] == 0
    finally:
        r.close()


def test_either_checksum_form_of_parameter_lines_is_accepted() -> None:
    r = Rig(emu={"semicolon_in_sum": True})
    try:
        ready(r)
        assert r.lidar.params is not None and r.lidar.params.dmax_mm == 60000
    finally:
        r.close()


def test_reboot_closes_the_link_and_the_driver_comes_back_after_the_boot() -> None:
    r = Rig(emu={"boot_time": 0.8})
    try:
        ready(r)
        assert r.lidar.reboot()
        r.run_until(lambda: r.lidar.state == DISCONNECTED)
        assert r.wire[-2:] == ["RB", "RB"] and r.emu.sensor.counters.reboots == 1
        took = r.run_until(lambda: r.lidar.state == READY, limit=3.0)
        assert 0.75 <= took <= 1.0  # it waited for the boot, not for a timeout
        assert r.wire[-4:] == HANDSHAKE
    finally:
        r.close()


def test_a_gd_meeting_a_laser_switched_off_behind_our_back_switches_it_on_again(rig: Rig
                                                                               ) -> None:
    ready(rig)
    rig.emu.sensor.feed(rig.clock.now(), b"QT\n")  # as if someone else had sent QT
    rig.emu.sensor.take_output()
    assert rig.lidar.request_scan()
    rig.run_until(lambda: rig.lidar.latest is not None)
    assert rig.wire[-4:] == ["QT", "GD0000108001", "BM", "GD0000108001"]


# -- the loop ---------------------------------------------------------------------------------
def test_a_scheduler_on_a_virtual_clock_drives_driver_and_emulator_through_its_io_wait() -> None:
    clock = VirtualClock()
    sched = Scheduler(clock, rate_hz=200)
    emu = HokuyoEmulator(clock)
    emu.attach(sched)
    lidar = HokuyoLidar(emu.url, clock=clock, loop=sched, stream=True)
    sched.add_task("hokuyo-emulator", 200, lambda now, dt: emu.service(now))
    sched.add_task("lidar", 100, lidar.tick)
    scans: list[Scan] = []
    lidar.add_listener(scans.append)
    try:
        lidar.start()
        deadline = time.monotonic() + 20
        while len(scans) < 40 and time.monotonic() < deadline:
            sched.run_for(0.1)
        assert lidar.state == STREAMING and len(scans) >= 40
        assert np.allclose(np.diff([s.sensor_time for s in scans]), 0.025)
        assert clock.now() < 2.0  # 40 scans take 1 s of clock time, whatever the wall
    finally:
        lidar.stop()
        emu.close()
    assert lidar.state == STOPPED and lidar.fileno() == -1


def test_stop_is_idempotent_and_says_qt_to_a_streaming_sensor() -> None:
    r = Rig(stream=True)
    try:
        r.start()
        r.run(0.2)
        r.lidar.stop()
        r.lidar.stop()
        r.emu.service()
        assert r.wire[-1] == "QT" and r.lidar.state == STOPPED
        r.run(0.1)
        assert r.lidar.stats["connects"] == 1  # stopped means stopped
    finally:
        r.close()


# -- configuration and the command line -------------------------------------------------------
@pytest.mark.parametrize(("text", "expected"), [
    ("192.168.0.10:10940", ("192.168.0.10", 10940)),
    ("192.168.0.10", ("192.168.0.10", 10940)),
    ("lidar.local:2000", ("lidar.local", 2000)),
    ("[fe80::1]:10940", ("fe80::1", 10940)),
    ("fe80::1", ("fe80::1", 10940)),
])
def test_addresses_are_host_colon_port(text: str, expected: tuple[str, int]) -> None:
    assert parse_address(text) == expected


@pytest.mark.parametrize(("text", "match"), [
    ("", "empty"), (":10940", "no host"), ("host:0", "1-65535"), ("host:http", "1-65535"),
    ("[::1", "unclosed"),
])
def test_bad_addresses_are_refused_with_the_reason(text: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        parse_address(text)


def test_bad_timing_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="reply_timeout must be a positive"):
        HokuyoLidar(clock=VirtualClock(), reply_timeout=0)
    with pytest.raises(ValueError, match="cluster must be 1-99"):
        HokuyoLidar(clock=VirtualClock(), cluster=0)


def test_the_check_command_prints_vv_pp_and_a_scan(capsys: pytest.CaptureFixture[str],
                                                   tmp_path: Path) -> None:
    """On the wall clock, as on the robot: the emulator answers from a real-time loop."""
    import threading

    pytest.importorskip("matplotlib")
    png = tmp_path / "scan.png"

    emu = HokuyoEmulator()  # wall clock (MonotonicClock-like) for the CLI's real-time loop
    stop = threading.Event()

    def serve() -> None:  # test harness thread: the emulator is the "other machine"
        while not stop.is_set():
            fds = [fd for fd in (emu.fileno(), emu.client_fileno) if fd >= 0]
            select.select(fds, [], [], 0.002)
            emu.service()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        assert main([emu.url, "--timeout", "10", "--stream", "5", "--plot", str(png)]) == 0
    finally:
        stop.set()
        thread.join(5)
        emu.close()
    out = capsys.readouterr().out
    assert "VV: Hokuyo Automatic Co.,Ltd. | SOKUIKI Sensor UTM-30LX-EW" in out
    assert "PP: UTM-30LX-EW, 23-60000 mm, steps 0..1080 (front 540, 1440 per turn" in out
    assert "scan: 1081 steps (0..1080), 1081 valid" in out and "stream: 5 scans" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f"plot: {png}" in out


def test_the_check_command_fails_clearly_when_nothing_answers(
        capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
        assert main([f"127.0.0.1:{port}", "--timeout", "0.3"]) == 1
    err = capsys.readouterr().err
    assert f"no answer from 127.0.0.1:{port} within 0.3 s" in err and "ECONNREFUSED" in err


@pytest.mark.parametrize("args, says", [
    (["--timeout", "nan"], "--timeout: expected seconds"),  # waited for ever
    (["--timeout", "1e308"], "--timeout: expected seconds"),
    (["--stream", "-5"], "--stream: expected 0-1000000 scans"),
])
def test_the_check_command_bounds_its_numbers(capsys: pytest.CaptureFixture[str],
                                              args: list[str], says: str) -> None:
    with pytest.raises(SystemExit) as info:
        main(["127.0.0.1:1", *args])
    assert info.value.code == 2
    assert says in capsys.readouterr().err
