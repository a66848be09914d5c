"""Motor (polarity, full duty, deadband) and BaseDrive mixing against SPEC 2.3."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ramp.hal.interfaces import MotorChannel
from ramp.layers.functional import Motor, mix
from ramp.modules.bucket_ladder import BucketLadder
from ramp.modules.skid_steer import BaseDrive, round_half_away


class FakeMotor(MotorChannel):
    """Records every duty written."""

    def __init__(self) -> None:
        super().__init__(None, "fake")  # type: ignore[arg-type]
        self.writes: list[float] = []

    def _apply(self, duty: float) -> None:
        self.writes.append(duty)


def spec_mix(s: float, d: float) -> tuple[float, float]:
    """SPEC 2.3 written out independently: L = s(cos+sin), R = s(cos-sin), scaled so the
    larger magnitude is |s|."""
    r = math.radians(d % 360)
    left = s * (math.cos(r) + math.sin(r))
    right = s * (math.cos(r) - math.sin(r))
    big = max(abs(left), abs(right))
    if big == 0:
        return 0.0, 0.0
    k = abs(s) / big
    return left * k, right * k


def make_drive() -> tuple[BaseDrive, list[FakeMotor]]:
    chans = [FakeMotor() for _ in range(4)]
    return BaseDrive(*(Motor(c) for c in chans)), chans


# -- Motor --------------------------------------------------------------------------------------
def test_motor_maps_percent_to_duty_and_reports_percent() -> None:
    ch = FakeMotor()
    m = Motor(ch)
    m.set_velocity(50)
    assert ch.duty == 0.5 and m.velocity == 50
    m.set_velocity(-100)
    assert ch.duty == -1.0 and m.velocity == -100
    m.stop()
    assert ch.duty == 0.0 and m.velocity == 0
    assert ch.writes == [0.5, -1.0, 0.0]


def test_motor_polarity_flips_the_duty_not_the_report() -> None:
    ch = FakeMotor()
    m = Motor(ch, polarity=-1)
    m.set_velocity(40)
    assert ch.duty == pytest.approx(-0.4)
    assert m.velocity == 40
    m.set_velocity(-25)
    assert ch.duty == pytest.approx(0.25)


def test_motor_full_duty_scales_100_percent() -> None:
    ch = FakeMotor()
    m = Motor(ch, full_duty=0.6)
    m.set_velocity(100)
    assert ch.duty == pytest.approx(0.6)
    m.set_velocity(-50)
    assert ch.duty == pytest.approx(-0.3)


def test_motor_deadband_sends_small_duties_as_zero() -> None:
    ch = FakeMotor()
    m = Motor(ch, full_duty=0.5, deadband=0.05)
    m.set_velocity(9)  # 0.045 < 0.05
    assert ch.duty == 0.0
    assert m.velocity == 9  # the commanded value is still what is reported
    m.set_velocity(-10)  # exactly 0.05: not smaller, goes out
    assert ch.duty == pytest.approx(-0.05)
    m.set_velocity(-9)
    assert ch.duty == 0.0


def test_motor_refuses_an_unchecked_velocity_and_bad_polarity() -> None:
    """The router validates every request; a velocity past 100 % reaching a motor is a bug
    above, reported, never clamped into something that moves (issue: request path)."""
    ch = FakeMotor()
    m = Motor(ch)
    m.set_velocity(60)
    with pytest.raises(AssertionError):
        m.set_velocity(250)
    assert ch.duty == pytest.approx(0.6) and m.velocity == 60  # nothing changed
    with pytest.raises(ValueError):
        ch.set_duty(1.5)  # nor does the HAL clamp
    assert ch.duty == pytest.approx(0.6)
    with pytest.raises(ValueError):
        Motor(ch, polarity=0)


def test_motor_from_params() -> None:
    ch = FakeMotor()
    m = Motor.from_params(ch, {"polarity": -1, "full_duty": 0.8, "deadband": 0.0})
    m.set_velocity(50)
    assert ch.duty == pytest.approx(-0.4)


# -- BaseDrive ----------------------------------------------------------------------------------
@pytest.mark.parametrize(("s", "d", "left", "right"), [
    (100, 0, 100, 100),
    (50, 0, 50, 50),
    (100, 45, 100, 0),          # pivots on the right side
    (100, 90, 100, -100),       # spin clockwise
    (100, -90, -100, 100),      # spin counter-clockwise
    (80, 180, -80, -80),        # straight back
    (100, 270, -100, 100),      # same as -90
    (100, 360 + 45, 100, 0),    # taken modulo 360
    (100, -45, 0, 100),         # pivots on the left side
    (100, 135, 0, -100),
    (100, -135, -100, 0),
    (-60, 0, -60, -60),
    (-100, 45, -100, 0),
    (0, 37.5, 0, 0),
    (100, 720, 100, 100),
    (100, -360 * 7 + 90, 100, -100),
])
def test_drive_key_directions(s: int, d: float, left: int, right: int) -> None:
    drive, chans = make_drive()
    assert drive.drive(s, d) == (left, right)
    lf, lb, rf, rb = (c.duty for c in chans)
    assert lf == lb == left / 100
    assert rf == rb == right / 100


@pytest.mark.parametrize("d", [30, 10.5, 22.5, 60, 89.9, 100, 150.25, 200, 300, -30, -100.7,
                               1e-3, 44.99, 45.01, 1000.3])
@pytest.mark.parametrize("s", [100, 73, -37, 1])
def test_drive_matches_spec_formula(s: int, d: float) -> None:
    drive, chans = make_drive()
    left, right = drive.drive(s, d)
    exp_l, exp_r = spec_mix(s, d)
    assert abs(left - exp_l) <= 0.5 + 1e-9
    assert abs(right - exp_r) <= 0.5 + 1e-9
    assert max(abs(left), abs(right)) == abs(s)
    assert chans[0].duty == chans[1].duty == left / 100
    assert chans[2].duty == chans[3].duty == right / 100


def test_drive_30_degrees_exact_values() -> None:
    # cos30 + sin30 = 1.366, cos30 - sin30 = 0.366 -> right = 100 * 0.366 / 1.366 = 26.79
    drive, _ = make_drive()
    assert drive.drive(100, 30) == (100, 27)
    assert drive.drive(-100, 30) == (-100, -27)  # mirrored exactly


@settings(max_examples=300, deadline=None)
@given(st.integers(-100, 100), st.floats(-1e6, 1e6, allow_nan=False))
def test_mix_property(s: int, d: float) -> None:
    left, right = mix(s, d)
    exp_l, exp_r = spec_mix(s, d)
    assert left == pytest.approx(exp_l, abs=1e-6)
    assert right == pytest.approx(exp_r, abs=1e-6)
    assert max(abs(round_half_away(left)), abs(round_half_away(right))) == abs(s)


def test_round_half_away_is_symmetric() -> None:
    assert [round_half_away(x) for x in (0.5, 1.5, 2.5, -0.5, -2.5, 0.49, -0.49)] == \
        [1, 2, 3, -1, -3, 0, 0]


def test_drive_stop_and_is_moving() -> None:
    drive, chans = make_drive()
    assert not drive.is_moving()
    drive.drive(40, 10)
    assert drive.is_moving()
    drive.stop()
    assert not drive.is_moving()
    assert [c.duty for c in chans] == [0.0] * 4


def test_drive_respects_each_wheels_polarity() -> None:
    chans = [FakeMotor() for _ in range(4)]
    drive = BaseDrive(Motor(chans[0]), Motor(chans[1]), Motor(chans[2], polarity=-1),
                      Motor(chans[3], polarity=-1))
    drive.drive(100, 0)
    assert [c.duty for c in chans] == [1.0, 1.0, -1.0, -1.0]
    assert [m.velocity for m in drive.wheels] == [100] * 4


def test_bucket_ladder_drives_both_chains_together() -> None:
    a, b = FakeMotor(), FakeMotor()
    chain = BucketLadder(Motor(a), Motor(b, polarity=-1))
    chain.vel(60)
    assert (a.duty, b.duty) == (pytest.approx(0.6), pytest.approx(-0.6))
    assert chain.velocity == 60 and chain.is_moving()
    chain.stop()
    assert (a.duty, b.duty) == (0.0, 0.0) and not chain.is_moving()
