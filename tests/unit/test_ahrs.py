"""AHRS: roll and pitch bounded by gravity whatever the gyro does, yaw held by the localizer,
and a shifted IMU mount noticed (parked, or from the scan's level) and corrected."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest

from firmware_like.imu import ImuEmulator
from ramp.autonomy.config import ImuConfig
from ramp.autonomy.hal.sim import SimImu
from ramp.autonomy.mount import Mount, angle_between
from ramp.autonomy.perception.ahrs import Ahrs, up_in_chassis
from ramp.clock import VirtualClock

Angles = Callable[[float], tuple[float, float, float]]


class Motion:
    """A chassis turning through given Z-Y-X angles over time (no translation): the truth an
    IMU emulator reads, body rates from the angles' derivatives."""

    def __init__(self, clock: VirtualClock, angles: Angles) -> None:
        self.clock = clock
        self.angles = angles

    def __call__(self) -> Motion:
        t = self.clock.now()
        self.roll, self.pitch, self.yaw = self.angles(t)
        h = 1e-4
        r1, p1, y1 = self.angles(t + h)
        dr, dp, dy = (r1 - self.roll) / h, (p1 - self.pitch) / h, (y1 - self.yaw) / h
        cr, sr = math.cos(self.roll), math.sin(self.roll)
        cp, sp = math.cos(self.pitch), math.sin(self.pitch)
        self.omega_body = (dr - dy * sp, dp * cr + dy * cp * sr, -dp * sr + dy * cp * cr)
        self.accel_body = (0.0, 0.0, 0.0)
        return self


class Bench:
    """An IMU emulator on the chassis motion, the `sim` driver, and the AHRS, ticked at 100 Hz."""

    def __init__(self, angles: Angles, *, seed: int = 1, fault: str = "none",
                 mount: Mount | None = None, moving: bool = False,
                 shift_window: tuple[float, float] = (5.0, 6.0)) -> None:
        self.clock = VirtualClock()
        self.motion = Motion(self.clock, angles)
        self.mount = mount or Mount(0.0, 0.1, 0.35)
        self.emulator = ImuEmulator(self.clock, self.motion, seed=seed, fault=fault,
                                    mount=self.mount, shift_window_s=shift_window)
        self.imu = SimImu(ImuConfig(driver="sim", mount=self.mount), emulator=self.emulator)
        self.imu.open(0.0)
        self.moving = moving
        self.ahrs = Ahrs(self.imu, self.mount, moving=lambda: self.moving)

    def run(self, seconds: float, every: Callable[[float], None] | None = None) -> None:
        for _ in range(round(seconds / 0.01)):
            self.clock.advance(0.01)
            now = self.clock.now()
            self.imu.tick(now, 0.01)
            self.ahrs.tick(now, 0.01)
            if every is not None:
                every(now)

    def tilt_error_deg(self) -> float:
        """Angle between the true up and the AHRS's, in the chassis frame."""
        t = self.motion()
        return math.degrees(angle_between(up_in_chassis(t.roll, t.pitch),
                                          up_in_chassis(self.ahrs.roll, self.ahrs.pitch)))

    def yaw_error_deg(self) -> float:
        return math.degrees(abs(math.remainder(self.ahrs.yaw - self.motion().yaw, 2 * math.pi)))


def rocking(t: float) -> tuple[float, float, float]:
    """Driving over uneven ground: +-3 deg of roll and pitch, turning slowly."""
    return (math.radians(3.0) * math.sin(0.9 * t), math.radians(3.0) * math.sin(0.6 * t + 1.0),
            0.05 * t)


def test_a_tilted_chassis_at_rest_reads_its_roll_and_pitch_through_a_turned_mount() -> None:
    roll, pitch = math.radians(4.0), math.radians(-6.0)
    bench = Bench(lambda t: (roll, pitch, 0.0),
                  mount=Mount(0.0, 0.1, 0.35, roll=180.0, yaw=90.0))  # upside down, across
    bench.run(3.0)
    assert bench.ahrs.settled and not bench.ahrs.suspect
    assert math.degrees(abs(bench.ahrs.roll - roll)) < 0.3
    assert math.degrees(abs(bench.ahrs.pitch - pitch)) < 0.3


def test_a_drifting_gyro_cannot_tilt_the_estimate_while_the_chassis_rocks() -> None:
    bench = Bench(rocking, fault="gyro-drift", moving=True)  # no still moments to re-zero in
    worst = 0.0

    def watch(now: float) -> None:
        nonlocal worst
        if now > 3.0:
            worst = max(worst, bench.tilt_error_deg())

    bench.run(120.0, watch)
    assert worst < 0.6  # a 0.15 deg/s drift integrated alone would be 18 deg by now
    assert bench.yaw_error_deg() > 2.0  # yaw has nothing to hold it: the drift is real


def test_the_localizers_yaw_holds_the_yaw_and_teaches_the_yaw_rate_bias() -> None:
    bench = Bench(rocking, fault="gyro-drift", moving=True)
    bench.ahrs.reset_yaw(0.0)
    between: list[float] = []

    def fix(now: float) -> None:
        if round(now * 100) % 200 == 0:  # a confident localization every 2 s
            between.append(bench.yaw_error_deg())
            bench.ahrs.correct_yaw(bench.motion().yaw, 0.9)

    bench.run(90.0, fix)
    assert max(between[-10:]) < 0.15  # drift between fixes once the bias is learned
    drift_z = bench.emulator.drift_mean_dps[2] + bench.emulator.gyro_bias_dps[2]
    assert math.degrees(bench.ahrs.gyro_bias[2]) == pytest.approx(drift_z, abs=0.03)


def test_the_first_yaw_fix_is_taken_whole_and_later_ones_by_their_weight() -> None:
    bench = Bench(lambda t: (0.0, 0.0, 1.0))
    bench.run(1.0)
    assert not bench.ahrs.yaw_known
    bench.ahrs.correct_yaw(1.0, 0.3)
    assert bench.ahrs.yaw_known and bench.ahrs.yaw == pytest.approx(1.0, abs=1e-9)
    bench.ahrs.correct_yaw(1.2, 0.5)
    assert bench.ahrs.yaw == pytest.approx(1.1, abs=1e-9)


def test_standing_still_measures_the_gyro_bias_so_yaw_does_not_wander() -> None:
    bench = Bench(lambda t: (0.01, -0.02, 0.5), seed=7)
    bench.run(2.5)
    bench.ahrs.reset_yaw(0.5)
    bench.run(60.0)
    assert bench.yaw_error_deg() < 0.3  # the board's bias (seeded) integrates to ~3 deg/min
    assert abs(bench.emulator.gyro_bias_dps[2]) * 60 > 1.0


def test_an_imu_shift_while_parked_is_folded_into_the_mount_and_flagged() -> None:
    roll, pitch = math.radians(1.5), math.radians(-2.0)
    bench = Bench(lambda t: (roll, pitch, 0.3), seed=4, fault="imu-shift")
    bench.run(4.9)
    assert not bench.ahrs.suspect and bench.tilt_error_deg() < 0.3
    shift = bench.emulator.fault_info()
    bench.run(3.0)
    assert bench.ahrs.suspect and "parked" in bench.ahrs.suspect_reason
    assert bench.ahrs.correction_deg == pytest.approx(shift["deg"], abs=0.3)
    assert bench.tilt_error_deg() < 0.3
    bench.run(10.0)  # and it stays right: the correction is in the readings, not the output
    assert bench.tilt_error_deg() < 0.3


def test_an_imu_shift_while_driving_is_caught_by_the_scans_level_and_stays_corrected() -> None:
    bench = Bench(rocking, seed=4, fault="imu-shift", moving=True)
    bench.run(8.0)
    shift = bench.emulator.fault_info()
    wrong = bench.tilt_error_deg()
    assert wrong == pytest.approx(shift["deg"], abs=1.0)  # believed: the chassis moves anyway
    assert not bench.ahrs.suspect
    t = bench.motion()
    bench.ahrs.level_hint(t.roll, t.pitch, 1.0, t=bench.clock.now())
    assert bench.ahrs.suspect and "scan" in bench.ahrs.suspect_reason
    assert bench.tilt_error_deg() < 0.3
    worst = 0.0

    def watch(now: float) -> None:
        nonlocal worst
        worst = max(worst, bench.tilt_error_deg())

    bench.run(60.0, watch)  # turning through 3 rad of yaw: the fix is in the chassis frame
    assert worst < 0.6


def test_a_level_hint_that_agrees_changes_nothing() -> None:
    bench = Bench(lambda t: (0.02, 0.03, 0.0))
    bench.run(3.0)
    before = bench.ahrs.attitude
    bench.ahrs.level_hint(0.02 + math.radians(0.3), 0.03, 1.0)
    assert bench.ahrs.attitude == before and not bench.ahrs.suspect
    assert bench.ahrs.correction_deg == 0.0 and bench.ahrs.hints == 1


def test_attitude_at_a_past_time_comes_from_the_history() -> None:
    bench = Bench(lambda t: (0.0, math.radians(2.0) * min(1.0, t / 10.0), 0.0), moving=True)
    bench.run(3.0)
    bench.run(4.0)
    past = bench.ahrs.attitude_at(5.0)[1]
    assert math.degrees(past) == pytest.approx(1.0, abs=0.15)  # pitch was 1 deg at t = 5
    assert bench.ahrs.attitude_at(-1.0) == bench.ahrs.attitude_at(0.0)


def test_a_fix_from_the_scan_while_parked_is_not_taken_for_the_imu_moving() -> None:
    roll, pitch = math.radians(1.0), math.radians(2.0)
    bench = Bench(lambda t: (roll, pitch, 0.0), seed=2, fault="imu-shift",
                  shift_window=(0.5, 0.6))  # shifted before the AHRS had a reference
    bench.run(3.0)
    assert bench.tilt_error_deg() > 4.0 and not bench.ahrs.suspect
    bench.ahrs.level_hint(roll, pitch, 1.0)
    bench.run(5.0)
    assert bench.ahrs.suspect and bench.tilt_error_deg() < 0.3
    assert bench.ahrs.correction_deg == pytest.approx(bench.emulator.shift_deg, abs=0.3)
