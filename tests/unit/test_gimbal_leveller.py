"""Gimbal levelling: the servo tilt that keeps the scanner's beam at a set elevation on a
tilted chassis, sent through the `sim` pan/tilt driver to the servo emulator, within the
servos' limits and speed."""

from __future__ import annotations

import math
import random

import pytest

from firmware_like.servo import gimbal_emulator
from ramp.autonomy.config import load_config
from ramp.autonomy.hal.sim import SimPanTilt
from ramp.autonomy.mount import Mount, lidar_pose, mat_vec, rotation_zyx
from ramp.autonomy.perception.gimbal import GimbalLeveller, servo_tilt_for
from ramp.clock import VirtualClock
from tests.unit.test_autonomy_config import EXAMPLE


def beam_elevation_down(roll: float, pitch: float, pan_deg: float, tilt_deg: float,
                        mount: Mount) -> float:
    """How far below the horizon the scanner's forward beam points (rad), from the mount
    code the scan records use."""
    _, rot = lidar_pose(mount, (0.0, 0.0, 0.0), pan_deg, tilt_deg)
    beam = mat_vec(rotation_zyx(roll, pitch, 0.0), (rot[0][0], rot[1][0], rot[2][0]))
    return -math.asin(beam[2])


@pytest.mark.parametrize("seed", range(5))
def test_the_solved_tilt_puts_the_beam_at_the_wanted_elevation(seed: int) -> None:
    rng = random.Random(seed)
    for _ in range(200):
        roll, pitch = math.radians(rng.uniform(-15, 15)), math.radians(rng.uniform(-15, 15))
        pan = math.radians(rng.uniform(-90, 90))
        want = math.radians(rng.uniform(-10, 40))
        mount = Mount(0.4, 0.0, 0.7, roll=rng.uniform(-3, 3), pitch=rng.uniform(-3, 3),
                      yaw=rng.uniform(-3, 3))
        tilt = servo_tilt_for(want, roll, pitch, pan, mount.rotation(), near=want)
        got = beam_elevation_down(roll, pitch, math.degrees(pan), math.degrees(tilt), mount)
        assert got == pytest.approx(want, abs=1e-9)


def test_signs_a_nose_down_chassis_tilts_the_scanner_up_and_a_left_roll_tilts_a_left_look_down(
        ) -> None:
    five = math.radians(5.0)
    assert servo_tilt_for(0.0, 0.0, five, 0.0) == pytest.approx(-five)
    assert servo_tilt_for(0.0, five, 0.0, math.pi / 2) == pytest.approx(five)
    assert servo_tilt_for(math.radians(20), 0.0, 0.0, 0.0) == pytest.approx(math.radians(20))


class Gimbal:
    """The MARTE gimbal from autonomy.yaml: emulator, `sim` driver, leveller at 100 Hz."""

    def __init__(self, roll_deg: float = 0.0, pitch_deg: float = 0.0) -> None:
        self.config = load_config(EXAMPLE).gimbal
        self.clock = VirtualClock()
        self.emulator = gimbal_emulator(self.clock, self.config)
        self.device = SimPanTilt(self.config, emulator=self.emulator)
        self.device.open(0.0)
        self.attitude = (math.radians(roll_deg), math.radians(pitch_deg))
        self.leveller = GimbalLeveller(self.device, lambda: self.attitude)

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / 0.01)):
            self.clock.advance(0.01)
            self.device.tick(self.clock.now(), 0.01)
            self.leveller.tick(self.clock.now(), 0.01)


def test_the_leveller_engages_and_levels_the_scanner_on_a_pitched_chassis() -> None:
    g = Gimbal(pitch_deg=-4.0)  # nose up 4 deg
    g.run(1.0)
    assert g.device.pan.engaged and g.leveller.settled and not g.leveller.saturated
    assert g.leveller.target == pytest.approx((0.0, 4.0), abs=1e-6)
    pan, tilt = g.emulator.angles()  # where the horns really are
    assert (pan, tilt) == pytest.approx((0.0, 4.0), abs=0.01)


def test_a_step_moves_no_faster_than_the_servos_velocity_limit() -> None:
    g = Gimbal()
    g.run(0.5)
    g.leveller.level(30.0)
    g.run(0.3)
    assert not g.leveller.settled
    speed = g.config.tilt.velocity_dps  # 60 deg/s in autonomy.yaml
    assert g.device.tilt.position_deg is not None
    assert g.device.tilt.position_deg <= speed * 0.3 + 1e-6
    g.run(0.6)
    assert g.leveller.settled and g.emulator.angles()[1] == pytest.approx(30.0, abs=0.01)


def test_beyond_the_servos_travel_it_saturates_and_says_so() -> None:
    g = Gimbal(pitch_deg=-20.0)  # nose up 20: 70 deg below the horizon needs 90 deg of tilt
    assert g.config.tilt.max_deg < 90.0
    g.leveller.level(70.0)
    g.run(2.5)
    assert g.leveller.saturated
    assert g.leveller.target is not None and g.leveller.target[1] == g.config.tilt.max_deg
    g.leveller.level(0.0)
    g.run(2.0)  # 60 deg back at the controller's 60 deg/s
    assert not g.leveller.saturated and g.leveller.settled


def test_a_set_point_correction_trims_the_tilt() -> None:
    g = Gimbal(pitch_deg=2.0)
    g.run(0.5)
    g.leveller.correct(-1.5)
    assert not g.leveller.settled
    g.run(0.5)
    assert g.leveller.target == pytest.approx((0.0, -3.5), abs=1e-6)
    assert g.leveller.settled
    with pytest.raises(ValueError, match="finite"):
        g.leveller.correct(math.nan)


def test_it_follows_the_chassis_and_waits_for_an_unplugged_board() -> None:
    g = Gimbal()
    g.run(0.5)
    g.attitude = (0.0, math.radians(3.0))
    g.run(0.5)
    assert g.emulator.angles()[1] == pytest.approx(-3.0, abs=0.01)
    g.emulator.unplug()
    g.run(0.2)
    assert not g.leveller.settled
    g.emulator.plug()
    g.run(1.0)
    assert g.leveller.settled and g.emulator.angles()[1] == pytest.approx(-3.0, abs=0.01)
