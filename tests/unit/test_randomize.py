"""`--randomize` (SPEC 6.3): the seed draws a robot that departs from the model, within the
SPEC's ranges, handed to the simulator's parts when they are built."""

from __future__ import annotations

import math

import pytest

from firmware_like.arena_params import LidarParams
from firmware_like.lidar_view import LidarView
from firmware_like.marte import MarteWorld
from firmware_like.marte_params import MarteParams
from firmware_like.randomize import Randomization
from ramp.simulation.mission import MissionOptions, make_world

RANGES = {
    "skid_efficiency_scale": (0.85, 1.15), "traction_scale": (0.85, 1.15),
    "wheel_speed_scale_lf": (0.95, 1.05), "wheel_speed_scale_rb": (0.95, 1.05),
    "lidar_mount_yaw_deg": (-1.0, 1.0), "lidar_mount_dx_m": (-0.01, 0.01),
    "lidar_mount_dy_m": (-0.01, 0.01), "gyro_bias_z_dps": (-0.2, 0.2),
    "load_cell_gain_scale": (0.97, 1.03), "battery_r_internal_scale": (1.0, 2.5),
    "battery_initial_soc": (0.85, 1.0),
}


def test_draws_are_the_seed_s_and_within_the_spec_s_ranges() -> None:
    assert Randomization.draw(7) == Randomization.draw(7) != Randomization.draw(8)
    for seed in range(50):
        drawn = Randomization.draw(seed).as_dict()
        for name, (lo, hi) in RANGES.items():
            assert lo <= drawn[name] <= hi, (seed, name, drawn[name])
    assert all(isinstance(v, float) for v in drawn.values())  # a flat name -> value object


def test_the_draws_reach_the_physics_and_the_sensors() -> None:
    r = Randomization.draw(3)
    p = r.marte_params(MarteParams())
    assert p.skid_efficiency == pytest.approx(min(1.0, 0.6 * r.skid_efficiency_scale))
    assert p.traction == pytest.approx(r.traction_scale)
    assert p.load_cell_gain == pytest.approx(0.02 * r.load_cell_gain_scale)
    assert p.initial_soc == r.battery_initial_soc
    assert r.imu_model().gyro_offset_dps == (r.gyro_bias_x_dps, r.gyro_bias_y_dps,
                                             r.gyro_bias_z_dps)
    world = MarteWorld.seeded(3, params=p)
    assert world.params is p
    # the mount's yaw turns every beam: straight ahead of the chassis is now off by it
    base = LidarParams()
    plain = LidarView.of(world, base).pose(1.0, 1.0, 0.0, 0.0, 0.0, 0.0)
    turned = LidarView.of(world, r.lidar_params(base)).pose(1.0, 1.0, 0.0, 0.0, 0.0, 0.0)
    ahead = turned.rotation @ [1.0, 0.0, 0.0]
    assert math.degrees(math.atan2(ahead[1], ahead[0])) == pytest.approx(
        r.lidar_mount_yaw_deg, abs=1e-6)
    assert plain.origin[0] - turned.origin[0] == pytest.approx(-r.lidar_mount_dx_m)


def test_a_wheel_s_speed_error_makes_the_robot_curve() -> None:
    straight = MarteWorld.seeded(0)
    skewed = MarteWorld.seeded(0, params=MarteParams(wheel_speed_scale=(1.05, 1.05, 0.95,
                                                                        0.95)))
    for w in (straight, skewed):
        w.place(5.5, 1.94, 0.0)
        for name, duty in (("base.lf_wheel", 0.5), ("base.lb_wheel", 0.5),
                           ("base.rf_wheel", -0.5), ("base.rb_wheel", -0.5)):  # forward
            w.set_motor(name, duty)
        w.step(3.0)
    assert abs(straight.heading_deg) < 0.5
    assert skewed.heading_deg < -1.0  # the left side runs faster: it turns right


def test_a_mission_without_randomize_keeps_the_model() -> None:
    assert make_world(MissionOptions(seed=3)).params == MarteParams()
    drawn = Randomization.draw(3)
    assert make_world(MissionOptions(seed=3), drawn).params == drawn.marte_params()
