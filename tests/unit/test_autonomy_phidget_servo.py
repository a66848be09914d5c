"""The autonomy's `phidget` gimbal driver against a fake Phidget22 package in sys.modules."""

from __future__ import annotations

import sys

import pytest

from ramp.autonomy.config import GimbalConfig, ServoConfig
from ramp.autonomy.hal import driver_class
from ramp.autonomy.hal.phidget_servo import PhidgetPanTilt
from ramp.common.phidget22 import RETRY_S
from ramp.errors import DeviceError
from tests.fake_phidget22 import (
    EPHIDGET_NOTATTACHED,
    FakeLibrary,
    FakeRCServo,
    install,
    on_library_thread,
)

PAN = ServoConfig("pan", channel=0, min_deg=-90, max_deg=90, velocity_dps=90,
                  acceleration_dps2=720, neutral_us=1500, us_per_deg=10)
TILT = ServoConfig("tilt", channel=3, min_deg=-30, max_deg=45, velocity_dps=60,
                   acceleration_dps2=360, neutral_us=1500, us_per_deg=10, reversed=True)


@pytest.fixture
def lib(monkeypatch: pytest.MonkeyPatch) -> FakeLibrary:
    return install(monkeypatch)


def open_gimbal(lib: FakeLibrary, **kw: object) -> tuple[PhidgetPanTilt, FakeRCServo,
                                                           FakeRCServo]:
    g = PhidgetPanTilt(GimbalConfig(pan=PAN, tilt=TILT, **kw))  # type: ignore[arg-type]
    g.open(0.0)
    return g, lib.of(FakeRCServo, 0), lib.of(FakeRCServo, 3)


def plug_both(pan: FakeRCServo, tilt: FakeRCServo) -> None:
    on_library_thread(lambda: (pan.plug(), tilt.plug()))


def test_registered_as_the_phidget_gimbal_driver() -> None:
    assert driver_class("gimbal", "phidget") is PhidgetPanTilt


def test_open_matches_each_axis_to_its_channel_and_does_not_wait(lib: FakeLibrary) -> None:
    g, pan, tilt = open_gimbal(lib, serial=91234)
    for ch, channel in ((pan, 0), (tilt, 3)):
        assert (ch.serial, ch.hub_port, ch.channel) == (91234, -1, channel)
        assert ch.calls[-1] == "open"
        assert "setOnTargetPositionReachedHandler" in ch.calls
        assert "setOnPositionChangeHandler" in ch.calls
    assert not g.attached and g.fault is None


def test_attach_maps_one_position_unit_to_one_gimbal_degree(lib: FakeLibrary) -> None:
    g, pan, tilt = open_gimbal(lib)
    plug_both(pan, tilt)
    g.tick(0.01, 0.01)
    assert g.attached and g.ready()
    assert (pan.min_pulse, pan.max_pulse, pan.min_pos, pan.max_pos) == (600, 2400, -90, 90)
    # Tilt is reversed: the controller is sent minus the gimbal angle.
    assert (tilt.min_pos, tilt.max_pos) == (-45, 30)
    assert (tilt.min_pulse, tilt.max_pulse) == (1050, 1800)
    assert pan.ramping and tilt.ramping and pan.data_interval == 20


def test_commands_wait_for_the_tick_and_go_out_in_order(lib: FakeLibrary) -> None:
    g, pan, tilt = open_gimbal(lib)
    g.point(30.0, 10.0)
    g.engage()
    plug_both(pan, tilt)
    assert pan.writes == []  # the attach handler itself writes nothing
    g.tick(0.01, 0.01)
    order = [k for k, _ in pan.writes if k in ("acceleration", "velocity", "engaged")]
    assert order == ["acceleration", "velocity"]  # engage waits for the target's write
    assert [p for p, _ in pan.pending] == [30.0]
    assert [p for p, _ in tilt.pending] == [-10.0]
    on_library_thread(lambda: (pan.complete(), tilt.complete()))
    g.tick(0.02, 0.01)
    assert pan.target == 30.0 and pan.engaged and tilt.target == -10.0 and tilt.engaged
    assert (pan.acceleration, pan.velocity_limit) == (720, 90)
    assert (tilt.acceleration, tilt.velocity_limit) == (360, 60)
    g.tick(0.03, 0.01)
    assert pan.pending == [] and tilt.pending == []  # nothing sent twice


def test_without_async_writes_the_blocking_setter_is_used(lib: FakeLibrary) -> None:
    g, pan, tilt = open_gimbal(lib)
    pan.async_supported = tilt.async_supported = False
    plug_both(pan, tilt)
    g.point(-20.0, 0.0)
    g.engage()
    g.tick(0.01, 0.01)
    assert pan.target == -20.0 and pan.engaged and tilt.target == 0.0


def test_positions_and_reached_events_come_back_in_gimbal_degrees(lib: FakeLibrary) -> None:
    g, pan, tilt = open_gimbal(lib)
    plug_both(pan, tilt)
    g.point(30.0, 10.0)
    g.engage()
    g.tick(0.01, 0.01)
    on_library_thread(lambda: (pan.complete(), tilt.complete()))
    g.tick(0.02, 0.01)
    on_library_thread(lambda: (pan.fire("position", 12.5), tilt.fire("position", -4.0)))
    g.tick(0.03, 0.01)
    assert g.angles() == (12.5, 4.0) and not g.reached
    on_library_thread(lambda: (pan.fire("reached", 30.0), tilt.fire("reached", -10.0)))
    g.tick(0.04, 0.01)
    assert g.angles() == (30.0, 10.0) and g.reached
    # News of an old target arriving after a new one was set does not count.
    g.pan.set_target(-45.0)
    on_library_thread(lambda: pan.fire("reached", 30.0))
    g.tick(0.05, 0.01)
    assert not g.pan.reached and g.pan.reached_count == 1


def test_a_refused_target_write_is_retried_a_little_later(lib: FakeLibrary) -> None:
    g, pan, tilt = open_gimbal(lib)
    plug_both(pan, tilt)
    g.point(5.0, 0.0)
    g.tick(0.01, 0.01)
    on_library_thread(lambda: (pan.complete(code=EPHIDGET_NOTATTACHED), tilt.complete()))
    g.tick(0.02, 0.01)  # the failure is seen here
    g.tick(0.02 + RETRY_S / 2, 0.01)
    assert pan.pending == []
    g.tick(0.03 + RETRY_S, 0.01)
    assert [p for p, _ in pan.pending] == [5.0]


def test_a_target_the_library_throws_back_is_not_lost(lib: FakeLibrary) -> None:
    g, pan, tilt = open_gimbal(lib)
    pan.async_supported = tilt.async_supported = False
    plug_both(pan, tilt)
    pan.refuse_targets = 1
    g.point(15.0, 0.0)
    g.engage()
    g.tick(0.01, 0.01)
    assert pan.target is None and not pan.engaged  # refused: nothing engaged on no target
    g.tick(0.02 + RETRY_S, 0.01)
    assert pan.target == 15.0 and pan.engaged


def test_detach_is_a_fault_and_reattach_sends_everything_again(lib: FakeLibrary) -> None:
    g, pan, tilt = open_gimbal(lib)
    plug_both(pan, tilt)
    g.point(20.0, 5.0)
    g.engage()
    g.tick(0.01, 0.01)
    on_library_thread(lambda: (pan.complete(), tilt.complete()))
    g.tick(0.02, 0.01)
    on_library_thread(tilt.unplug)
    g.tick(0.03, 0.01)  # no exception
    assert isinstance(g.fault, DeviceError) and g.fault.device == "gimbal.tilt"
    assert "RCServo channel 3 detached" in str(g.fault)
    assert not g.ready() and g.tilt.position_deg is None
    on_library_thread(tilt.plug)  # the board comes back having forgotten everything
    assert tilt.target is None and not tilt.engaged
    g.tick(1.0, 0.01)
    on_library_thread(tilt.complete)
    g.tick(1.01, 0.01)
    assert g.fault is None and g.ready()
    assert tilt.target == -5.0 and tilt.engaged and tilt.velocity_limit == 60


def test_a_controller_that_never_attaches_names_the_missing_axes(lib: FakeLibrary) -> None:
    g, pan, _tilt = open_gimbal(lib, serial=7, attach_timeout_s=1.0)
    on_library_thread(pan.plug)
    g.tick(1.5, 0.01)
    assert g.fault is not None and g.fault.device == "gimbal.tilt"
    assert "tilt (channel 3)" in str(g.fault) and "pan" not in str(g.fault).split(":")[-1]


def test_close_closes_both_channels_once(lib: FakeLibrary) -> None:
    g, pan, tilt = open_gimbal(lib)
    plug_both(pan, tilt)
    g.tick(0.01, 0.01)
    with g:
        pass
    g.close()
    assert (pan.close_count, tilt.close_count) == (1, 1) and not g.attached


def test_without_phidget22_opening_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch
                                                           ) -> None:
    for name in [m for m in sys.modules if m.split(".")[0] == "Phidget22"] + ["Phidget22"]:
        monkeypatch.setitem(sys.modules, name, None)  # the real package is installed
    g = PhidgetPanTilt(GimbalConfig(pan=PAN, tilt=TILT))
    with pytest.raises(DeviceError, match=r"pip install 'ramp\[phidget\]'"):
        g.open(0.0)
    assert not g.is_open
