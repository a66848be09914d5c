"""The autonomy's `phidget` IMU driver against a fake Phidget22 package in sys.modules."""

from __future__ import annotations

import logging
import sys
import threading

import pytest

from ramp.autonomy.config import ImuConfig
from ramp.autonomy.hal import driver_class
from ramp.autonomy.hal.phidget_spatial import PhidgetImu
from ramp.errors import DeviceError
from tests.fake_phidget22 import PUNK_DBL, FakeLibrary, FakeSpatial, install, on_library_thread


@pytest.fixture
def lib(monkeypatch: pytest.MonkeyPatch) -> FakeLibrary:
    return install(monkeypatch)


def open_imu(lib: FakeLibrary, **kw: object) -> tuple[PhidgetImu, FakeSpatial]:
    imu = PhidgetImu(ImuConfig(**kw))  # type: ignore[arg-type]
    imu.open(0.0)
    return imu, lib.of(FakeSpatial)


def level(ch: FakeSpatial, ms: float, gz: float = 0.0) -> None:
    ch.send([0.0, 0.0, -1.0], [0.0, 0.0, gz], [0.2, 0.0, -0.4], ms)


def test_registered_as_the_phidget_imu_driver() -> None:
    assert driver_class("imu", "phidget") is PhidgetImu
    assert PhidgetImu.driver_name == "phidget"


def test_open_sets_matching_and_handlers_before_open_and_does_not_wait(lib: FakeLibrary) -> None:
    imu, ch = open_imu(lib, serial=370123, hub_port=-1, channel=0)
    assert (ch.serial, ch.hub_port, ch.channel) == (370123, -1, 0)
    assert ch.calls.index("open") > max(ch.calls.index(c) for c in (
        "setDeviceSerialNumber", "setHubPort", "setChannel", "setOnAttachHandler",
        "setOnDetachHandler", "setOnErrorHandler", "setOnSpatialDataHandler"))
    assert imu.is_open and not imu.attached and not imu.ready()
    imu.tick(0.01, 0.01)
    assert imu.fault is None  # still inside the attach timeout


def test_attach_sets_the_data_interval_clamped_to_the_board(lib: FakeLibrary) -> None:
    imu, ch = open_imu(lib, data_interval_ms=2)
    on_library_thread(ch.plug)
    assert ch.data_interval is None  # the handler itself does nothing but enqueue
    imu.tick(0.01, 0.01)
    assert ch.data_interval == 4 == imu.data_interval_ms  # the fake's minimum
    assert imu.attached and imu.ready()


def test_samples_from_a_library_thread_are_drained_in_the_tick(lib: FakeLibrary) -> None:
    imu, ch = open_imu(lib)
    on_library_thread(ch.plug)
    imu.tick(0.01, 0.01)

    def lib_thread() -> None:
        ch.send([0.01, -0.02, -0.99], [1.5, -2.0, 30.0], [0.21, 0.01, -0.41], 1000.0)
        ch.send([0.0, 0.0, -1.0], [0.0, 0.0, 0.0], [PUNK_DBL] * 3, 1008.0)

    on_library_thread(lib_thread)
    assert imu.drain() == []  # nothing moves until the tick
    imu.tick(0.02, 0.01)
    a, b = imu.drain()
    assert threading.get_ident() not in ch.handler_threads
    assert a.accel_g == (0.01, -0.02, -0.99) and a.gyro_dps == (1.5, -2.0, 30.0)
    assert a.mag_gauss == (0.21, 0.01, -0.41) and b.mag_gauss is None
    assert (a.timestamp_ms, b.timestamp_ms) == (1000.0, 1008.0)
    assert b.t - a.t == pytest.approx(0.008)  # the board's spacing, not the USB's
    assert b.t <= 0.02  # never in the future
    assert a.specific_force_g == (-0.01, 0.02, 0.99)
    assert imu.drain() == [] and imu.latest == b and imu.received == 2


def test_a_steady_stream_keeps_order_and_loses_nothing(lib: FakeLibrary) -> None:
    imu, ch = open_imu(lib)
    on_library_thread(ch.plug)
    imu.tick(0.01, 0.01)
    n = 2000
    done = threading.Event()

    def lib_thread() -> None:
        for i in range(n):
            level(ch, 8.0 * i, gz=float(i))
        done.set()

    t = threading.Thread(target=lib_thread)
    t.start()
    now, got = 0.01, []
    while not done.is_set():
        now += 0.01
        imu.tick(now, 0.01)
        got += imu.drain()
    t.join(5.0)
    imu.tick(now + 0.01, 0.01)
    got += imu.drain()
    assert [s.gyro_dps[2] for s in got] == [float(i) for i in range(n)]
    times = [s.t for s in got]
    assert times == sorted(times)


def test_a_board_clock_running_ahead_never_sends_sample_times_backwards(
        lib: FakeLibrary) -> None:
    # The steady-stream test above found this only when the library thread outran the ticks:
    # a stretch whose board time runs ahead pulls the anchor back, and its first samples were
    # timed before the last one already handed on.
    imu, ch = open_imu(lib)
    on_library_thread(ch.plug)
    imu.tick(0.01, 0.01)
    for i in range(11):  # 0..80 ms of board time by the tick at 0.02
        on_library_thread(lambda ms=8.0 * i: level(ch, ms))
    imu.tick(0.02, 0.01)
    first = imu.drain()
    for i in range(11, 51):  # 88..400 ms of board time by the tick at 0.03: far ahead
        on_library_thread(lambda ms=8.0 * i: level(ch, ms))
    imu.tick(0.03, 0.01)
    times = [s.t for s in first + imu.drain()]
    assert len(times) == 51
    assert times == sorted(times)
    assert times[-1] <= 0.03  # and still never in the future


def test_detach_is_a_fault_and_reattach_clears_it(lib: FakeLibrary,
                                                  caplog: pytest.LogCaptureFixture) -> None:
    imu, ch = open_imu(lib, serial=42)
    on_library_thread(lambda: (ch.plug(), level(ch, 5000.0)))
    imu.tick(0.01, 0.01)
    with caplog.at_level(logging.WARNING, logger="ramp.autonomy.hal"):
        on_library_thread(ch.unplug)
        imu.tick(0.02, 0.01)  # no exception from the tick
    assert not imu.attached and not imu.ready()
    assert isinstance(imu.fault, DeviceError)
    assert str(imu.fault) == "bus imu: PhidgetSpatial (serial 42, channel 0) detached"
    assert any("detached" in r.getMessage() for r in caplog.records)
    # The library re-attaches the same open channel; the board restarts its timestamp.
    on_library_thread(lambda: (ch.plug(), level(ch, 0.0), level(ch, 8.0)))
    imu.tick(1.0, 0.01)
    assert imu.ready() and imu.fault is None
    assert ch.data_interval == 8  # set again: the board forgot it
    old, new1, new2 = imu.drain()
    assert new1.t >= old.t and new2.t - new1.t == pytest.approx(0.008)


def test_a_board_that_never_attaches_is_a_fault_naming_it(lib: FakeLibrary) -> None:
    imu, ch = open_imu(lib, serial=4242, attach_timeout_s=2.0)
    imu.tick(1.9, 0.01)
    assert imu.fault is None
    imu.tick(2.1, 0.01)
    assert imu.fault is not None and "not attached within 2 s" in str(imu.fault)
    on_library_thread(ch.plug)  # late, but welcome
    imu.tick(2.2, 0.01)
    assert imu.fault is None and imu.attached


def test_an_attached_but_silent_board_is_a_fault(lib: FakeLibrary) -> None:
    imu, ch = open_imu(lib)
    on_library_thread(ch.plug)
    imu.tick(0.0, 0.01)
    imu.tick(0.4, 0.01)
    assert imu.fault is None
    imu.tick(0.6, 0.01)
    assert imu.fault is not None and "no sample for" in str(imu.fault)
    on_library_thread(lambda: level(ch, 600.0))
    imu.tick(0.61, 0.01)
    assert imu.fault is None


def test_zero_gyro_reaches_the_board_only_when_attached(lib: FakeLibrary) -> None:
    imu, ch = open_imu(lib)
    with pytest.raises(DeviceError, match="not attached"):
        imu.zero_gyro()
    on_library_thread(ch.plug)
    imu.tick(0.01, 0.01)
    imu.zero_gyro()
    assert ch.zeroed == 1


def test_close_closes_the_channel_once_and_late_events_are_ignored(lib: FakeLibrary) -> None:
    imu, ch = open_imu(lib)
    on_library_thread(ch.plug)
    imu.tick(0.01, 0.01)
    imu.close()
    imu.close()
    assert ch.close_count == 1 and not imu.is_open
    imu.open(1.0)  # a fresh channel object and queue
    new = lib.of(FakeSpatial)
    assert new is not ch
    on_library_thread(lambda: level(ch, 9.0))  # the old handle's handler still fires
    imu.tick(1.01, 0.01)
    assert imu.drain() == [] and not imu.attached


def test_without_phidget22_opening_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch
                                                           ) -> None:
    for name in [m for m in sys.modules if m.split(".")[0] == "Phidget22"] + ["Phidget22"]:
        monkeypatch.setitem(sys.modules, name, None)  # the real package is installed
    imu = PhidgetImu(ImuConfig())
    with pytest.raises(DeviceError) as info:
        imu.open(0.0)
    assert "Phidget22 package is not installed" in str(info.value)
    assert "pip install 'ramp[phidget]'" in str(info.value)
    assert isinstance(info.value.__cause__, ImportError)
    assert not imu.is_open


def test_a_missing_native_library_is_a_clear_error(lib: FakeLibrary) -> None:
    lib.constructor_error = OSError("libusb-1.0.so.0: cannot open shared object file")
    imu = PhidgetImu(ImuConfig())
    with pytest.raises(DeviceError, match="libusb-1.0.so.0.*apt-get install libusb-1.0-0"):
        imu.open(0.0)
