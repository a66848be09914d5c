"""The RC servo emulator: real speed, limits, the target-reached event, the horn's lag."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_like.servo import HS5645MG_SPEED_DPS, PanTiltEmulator, ServoEmulator
from ramp.clock import VirtualClock


def servo(clock: VirtualClock, **kw: float) -> ServoEmulator:
    args = {"min_deg": -90.0, "max_deg": 90.0, "velocity_limit_dps": 90.0,
            "acceleration_dps2": 720.0}
    args.update(kw)
    return ServoEmulator(clock, **args)


def engaged_at(clock: VirtualClock, deg: float = 0.0, **kw: float) -> ServoEmulator:
    s = servo(clock, **kw)
    s.set_target(deg)
    s.set_engaged(True)
    assert s.take_reached() == [deg]  # engaging jumps to the target: reached at once
    return s


def test_a_move_ramps_up_cruises_at_the_velocity_limit_and_lands_on_the_target() -> None:
    clock = VirtualClock()
    s = engaged_at(clock)
    s.set_target(90.0)
    clock.advance(0.0625)  # half the ramp-up time (90 / 720 = 0.125 s)
    assert s.velocity_dps == pytest.approx(45.0)
    assert s.position_deg == pytest.approx(0.5 * 720 * 0.0625**2)
    clock.advance(0.5)
    assert s.velocity_dps == pytest.approx(90.0) and s.moving
    # Trapezoid: 90 deg at 90 deg/s with 720 deg/s^2 ramps takes 90/90 + 90/720 = 1.125 s.
    clock.set(1.12)
    assert s.take_reached() == [] and s.position_deg < 90.0
    clock.set(1.125)
    assert s.position_deg == 90.0 and s.velocity_dps == 0.0 and not s.moving
    assert s.take_reached() == [90.0]
    clock.advance(1.0)
    assert s.take_reached() == []  # once per arrival


def test_the_same_motion_however_often_it_is_looked_at() -> None:
    a_clock, b_clock = VirtualClock(), VirtualClock()
    a, b = engaged_at(a_clock), engaged_at(b_clock)
    a.set_target(-60.0)
    b.set_target(-60.0)
    for _ in range(70):
        a_clock.advance(0.01)
        a.advance()
    b_clock.advance(0.7)
    assert a.position_deg == pytest.approx(b.position_deg, abs=1e-9)


def test_targets_outside_the_limits_are_refused_and_change_nothing() -> None:
    clock = VirtualClock()
    s = engaged_at(clock, 10.0, min_deg=-30.0, max_deg=45.0)
    for bad in (45.5, -31.0, float("nan")):
        with pytest.raises(ValueError, match="outside -30..45"):
            s.set_target(bad)
    assert s.target_deg == 10.0
    with pytest.raises(ValueError):
        servo(clock, min_deg=10.0, max_deg=10.0)


def test_a_new_target_mid_move_turns_back_without_leaving_the_limits() -> None:
    clock = VirtualClock()
    s = engaged_at(clock, -80.0, velocity_limit_dps=200.0, acceleration_dps2=400.0)
    s.set_target(89.0)
    clock.advance(0.6)
    s.set_target(-90.0)  # at speed toward +90: must brake first, then come back
    seen = []
    for _ in range(400):
        clock.advance(0.01)
        seen.append(s.position_deg)
    assert all(-90.0 <= p <= 90.0 for p in seen if p is not None)
    assert s.position_deg == -90.0 and s.take_reached() == [-90.0]


def test_the_horn_lags_when_the_controller_asks_more_than_the_servo_can() -> None:
    clock = VirtualClock()
    s = engaged_at(clock, velocity_limit_dps=1000.0, acceleration_dps2=1e5)
    s.set_target(90.0)
    clock.advance(0.1)
    assert s.position_deg == pytest.approx(90.0)  # the pulse is there already ...
    assert s.angle_at() == pytest.approx(0.1 * HS5645MG_SPEED_DPS)  # ... the horn is not
    clock.advance(1.0)
    assert s.angle_at() == 90.0


def test_disengaged_it_reports_no_position_and_the_horn_stays() -> None:
    clock = VirtualClock()
    s = servo(clock, start_deg=20.0)
    with pytest.raises(ValueError, match="needs a target"):
        s.set_engaged(True)
    assert s.position_deg is None and s.angle_at() == 20.0
    s.set_target(-10.0)
    clock.advance(1.0)
    assert s.angle_at() == 20.0  # no pulses, no motion
    s.set_engaged(True)
    assert s.position_deg == -10.0  # the controller jumps, the horn swings at its speed
    clock.advance(0.05)
    assert s.angle_at() == pytest.approx(20.0 - 0.05 * HS5645MG_SPEED_DPS)


def test_unplugging_the_board_drops_every_setting() -> None:
    clock = VirtualClock()
    g = PanTiltEmulator(clock, engaged_at(clock, 30.0), engaged_at(clock, 5.0))
    clock.advance(1.0)
    g.unplug()
    assert not g.attached and g.pan.target_deg is None and not g.pan.engaged
    assert g.angles() == (30.0, 5.0)  # the servos go limp where they were
    g.plug()
    assert g.attached and g.tilt.position_deg is None


@settings(max_examples=40, deadline=None)
@given(moves=st.lists(st.tuples(st.floats(-45.0, 60.0), st.floats(0.001, 0.5)),
                      min_size=1, max_size=12),
       vmax=st.floats(5.0, 400.0), acc=st.floats(50.0, 5000.0))
def test_any_sequence_of_targets_stays_in_limits_and_ends_on_the_last(
        moves: list[tuple[float, float]], vmax: float, acc: float) -> None:
    clock = VirtualClock()
    s = engaged_at(clock, 0.0, min_deg=-45.0, max_deg=60.0, velocity_limit_dps=vmax,
                   acceleration_dps2=acc)
    for target, wait in moves:
        s.set_target(target)
        clock.advance(wait)
        p = s.position_deg
        assert p is not None and -45.0 - 1e-9 <= p <= 60.0 + 1e-9
        assert abs(s.velocity_dps) <= vmax + 1e-6
    clock.advance(105.0 / vmax + 2.0 * vmax / acc + 1.0)
    assert s.position_deg == moves[-1][0] and not s.moving
