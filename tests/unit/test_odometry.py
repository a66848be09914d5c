"""Odometry: the drive commands the autonomy sent, integrated with the planner's MARTE model,
against the simulator's MARTE moving on the same commands."""

from __future__ import annotations

import math

import pytest

from firmware_like.marte import MarteWorld
from ramp.autonomy.odometry import Odometry, between, compose
from ramp.autonomy.robot_model import MARTE, wheel_mix


def drive_world(world: MarteWorld, speed: float, direction: float) -> None:
    """What the backend does with `base.drive`: SPEC 2.3's mix, the right side mirrored."""
    left, right = wheel_mix(speed, direction)
    for name in ("base.lf_wheel", "base.lb_wheel"):
        world.set_motor(name, left / 100.0)
    for name in ("base.rf_wheel", "base.rb_wheel"):
        world.set_motor(name, -right / 100.0)


def test_straight_ahead_at_full_speed_reaches_the_free_speed_after_the_motor_lag() -> None:
    odo = Odometry()
    odo.command(0.0, 100, 0)
    odo.advance(10.0)
    x, y, yaw = odo.pose
    # 10 s at 0.299 m/s, minus the 0.15 s lag's share: v * (10 - tau)
    assert x == pytest.approx(MARTE.wheel_free_speed_m_s * (10.0 - 0.15), abs=1e-3)
    assert y == pytest.approx(0.0, abs=1e-12) and yaw == pytest.approx(0.0, abs=1e-12)
    assert odo.moving


def test_direction_90_spins_clockwise_and_stopping_spins_down() -> None:
    odo = Odometry()
    odo.command(0.0, 50, 90)
    odo.advance(2.0)
    spin = MARTE.body_velocity(50, -50)[1]  # clockwise: negative yaw rate
    assert spin < 0
    assert odo.pose[2] == pytest.approx(spin * (2.0 - 0.15), abs=1e-3)
    assert odo.pose[:2] == pytest.approx((0.0, 0.0), abs=1e-12)
    odo.stop(2.0)
    odo.advance(4.0)
    assert not odo.moving


def test_the_model_follows_the_simulated_robot_through_a_drive_with_turns() -> None:
    world = MarteWorld()  # empty, level arena: no slip but the model's
    odo = Odometry(now=0.0)
    start = (world.x, world.y, world.heading)
    t = 0.0
    plan = [(60, 0, 3.0), (40, -30, 2.0), (50, 90, 1.5), (70, 20, 3.0), (0, 0, 1.0)]
    for speed, direction, seconds in plan:
        drive_world(world, speed, direction)
        odo.command(t, speed, direction)
        for _ in range(round(seconds / 0.01)):
            odo.set_rail_voltage(world.battery_voltage)  # as `base:battery.volt` tells it
            world.step(0.01)
            t += 0.01
            odo.advance(t)
    moved = between(start, (world.x, world.y, world.heading))
    assert odo.distance_m > 1.0
    assert odo.pose[0] == pytest.approx(moved[0], abs=0.02)
    assert odo.pose[1] == pytest.approx(moved[1], abs=0.02)
    assert math.degrees(abs(math.remainder(odo.pose[2] - moved[2], 2 * math.pi))) < 0.5


def test_relative_motion_between_two_scan_times_comes_from_the_history() -> None:
    odo = Odometry(now=0.0)
    odo.command(0.0, 100, 0)
    for k in range(1, 301):
        odo.advance(k * 0.01)
    a, b = odo.pose_at(1.0), odo.pose_at(2.5)
    assert a[0] < b[0]
    dx, dy, dyaw = odo.relative(1.0, 2.5)
    assert dx == pytest.approx(b[0] - a[0], abs=1e-9) and dy == pytest.approx(0.0, abs=1e-9)
    assert odo.pose_at(-5.0) == odo.pose_at(0.0)  # clamped to the history's ends
    assert odo.pose_at(99.0) == odo.pose


def test_compose_and_between_undo_each_other() -> None:
    a = (1.0, 2.0, 0.7)
    b = (3.5, -1.0, -2.9)
    d = between(a, b)
    assert compose(a, d) == pytest.approx(b)


def test_reset_puts_the_pose_where_the_localizer_says() -> None:
    odo = Odometry()
    odo.command(0.0, 100, 0)
    odo.advance(1.0)
    odo.reset(1.0, (2.0, 1.0, math.pi / 2))
    odo.advance(2.0)  # still driving: forward is now +y
    assert odo.pose[0] == pytest.approx(2.0, abs=1e-9) and odo.pose[1] > 1.25
