"""The path follower drives a skid-steer model (the backend's own SPEC 2.3 mix, the simulator's
MARTE numbers) along paths to their goals, forwards and backwards; the command mapping."""

from __future__ import annotations

import json
import math
import random

import numpy as np
import pytest

from firmware_like.marte_params import MarteParams
from ramp.autonomy.planning import (
    DriveCommand,
    Path,
    PathFollower,
    Planner,
    Pose,
    plan_to_dock,
)
from ramp.autonomy.robot_model import MARTE, drive_command, wheel_mix
from ramp.layers.functional.base_drive import mix
from ramp.simulation.referee import referee
from tests.unit.rmc_layouts import random_layout, random_start, sampled_clearance

PARAMS = MarteParams()


class SkidSteer:
    """MARTE's base as the simulator models it: first-order wheel lag, skid losses."""

    def __init__(self, pose: Pose) -> None:
        self.x, self.y, self.yaw = pose.x, pose.y, pose.yaw
        self.left = self.right = 0.0
        self.trail: list[tuple[float, float, float]] = []

    @property
    def pose(self) -> Pose:
        return Pose(self.x, self.y, self.yaw)

    def step(self, cmd: DriveCommand, dt: float = 0.1) -> None:
        target_l, target_r = mix(cmd.speed, cmd.direction)  # the backend's own mixing
        v_free = PARAMS.wheel_free_speed
        for _ in range(5):
            h = dt / 5
            a = 1.0 - math.exp(-h / PARAMS.motor_time_constant)
            self.left += (target_l - self.left) * a
            self.right += (target_r - self.right) * a
            vl, vr = self.left / 100 * v_free, self.right / 100 * v_free
            v = 0.5 * (vl + vr)
            w = PARAMS.skid_efficiency * (vr - vl) / PARAMS.track_width  # CCW in SPEC 6.1
            mid = self.yaw + 0.5 * w * h
            self.x += v * math.cos(mid) * h
            self.y += v * math.sin(mid) * h
            self.yaw += w * h
        self.trail.append((self.x, self.y, self.yaw))


def follow(path: Path, robot: SkidSteer, limit_s: float = 300.0) -> list[DriveCommand]:
    follower = PathFollower(path)
    cmds = []
    for _ in range(int(limit_s / 0.1)):
        cmd = follower.update(robot.pose)
        cmds.append(cmd)
        if cmd.status in ("done", "off_path"):
            return cmds
        robot.step(cmd)
    raise AssertionError("the follower never finished")


def test_the_autonomy_model_uses_the_simulators_marte_numbers() -> None:
    assert MARTE.wheel_free_speed_m_s == pytest.approx(PARAMS.wheel_free_speed)
    assert MARTE.track_width_m == PARAMS.track_width
    assert MARTE.skid_efficiency == PARAMS.skid_efficiency
    assert (MARTE.length_m, MARTE.width_m) == (PARAMS.robot_length, PARAMS.robot_width)


def test_drive_command_is_the_exact_inverse_of_the_spec_mix() -> None:
    rng = random.Random(1)
    for _ in range(200):
        left, right = rng.uniform(-100, 100), rng.uniform(-100, 100)
        speed, direction = drive_command(left, right)
        assert mix(speed, direction) == pytest.approx((left, right))
        assert wheel_mix(speed, direction) == pytest.approx((left, right))
    assert drive_command(40, 40) == (40, 0.0)
    assert drive_command(-40, -40) == pytest.approx((40, 180.0))
    assert drive_command(30, -30) == pytest.approx((30, 90.0))  # clockwise spin
    assert drive_command(-30, 30) == pytest.approx((30, -90.0))


def test_follows_an_l_shaped_path_to_the_goal_and_final_heading() -> None:
    path = Path(np.array([[1.0, 1.0], [3.0, 1.0], [3.0, 2.5]]), final_yaw=math.pi)
    robot = SkidSteer(Pose(1.0, 1.0, 0.0))
    cmds = follow(path, robot)
    assert cmds[-1].status == "done"
    assert math.hypot(robot.x - 3.0, robot.y - 2.5) < 0.05
    assert abs(math.remainder(robot.yaw - math.pi, 2 * math.pi)) < math.radians(3)
    trail = np.array(robot.trail)
    # It turned at the corner rather than cutting it: never far from the two legs.
    off = np.minimum(np.abs(trail[:, 1] - 1.0) + np.maximum(trail[:, 0] - 3.05, 0),
                     np.abs(trail[:, 0] - 3.0) + np.maximum(1.0 - trail[:, 1], 0))
    assert off.max() < 0.06
    assert any(c.status == "turning" and c.direction == pytest.approx(-90) for c in cmds)


def test_backs_straight_onto_the_collector_wall_in_reverse() -> None:
    path = Path(np.linspace([1.6, 1.94], [0.6, 1.94], 11), reverse=True)
    robot = SkidSteer(Pose(1.6, 1.98, math.radians(3)))  # a little off line and heading
    cmds = follow(path, robot)
    assert cmds[-1].status == "done"
    assert robot.x - 0.6 < 0.04 and abs(robot.y - 1.94) < 0.015
    assert abs(math.remainder(robot.yaw, 2 * math.pi)) < math.radians(2.5)
    moving = [c for c in cmds if c.status == "following"]
    assert moving and all(abs(abs(c.direction) - 180) < 30 for c in moving)


def test_slows_down_before_the_goal() -> None:
    path = Path(np.linspace([1.0, 2.0], [3.0, 2.0], 21))
    robot = SkidSteer(Pose(1.0, 2.0, 0.0))
    cmds = [c for c in follow(path, robot) if c.status == "following"]
    cruise = max(c.speed for c in cmds)
    near = [c.speed for c in cmds if c.remaining_m < 0.05]
    assert cruise == 60 and near and max(near) < 0.4 * cruise
    # A constant deceleration: a decimetre out it still runs at half speed. Speed falling in
    # proportion to the distance left crept the last decimetres at the floor, 2-3 s a stop.
    decimetre = [c.speed for c in cmds if 0.08 < c.remaining_m < 0.12]
    assert decimetre and min(decimetre) >= 0.4 * cruise
    assert [c.remaining_m for c in cmds] == sorted((c.remaining_m for c in cmds), reverse=True)


def test_reports_off_path_and_stops_when_pushed_aside() -> None:
    follower = PathFollower(Path(np.linspace([1.0, 2.0], [4.0, 2.0], 31)))
    assert follower.update(Pose(1.5, 2.0, 0.0)).status == "following"
    cmd = follower.update(Pose(2.0, 2.4, 0.0))
    assert (cmd.status, cmd.speed) == ("off_path", 0)
    assert cmd.cross_track_m == pytest.approx(0.4)
    assert cmd.request == "base:base.drive=(0,0)"
    assert follower.update(Pose(2.0, 2.0, 0.0)).status == "off_path"  # until reset


@pytest.mark.parametrize("seed", [2, 5])
def test_planned_trip_and_docking_driven_by_the_model_keep_the_footprint_clear(
        seed: int) -> None:
    rng = random.Random(seed)
    arena = random_layout(rng)
    planner = Planner(arena)
    start = random_start(rng, ("left", "right")[seed % 2], 90 * (seed % 4))
    robot = SkidSteer(start)
    plan = planner.plan(start, (5.4, 1.5), 0.0)
    assert plan.ok, plan.reason
    for leg in plan.legs:
        assert follow(leg, robot)[-1].status == "done"
    dock_plan, dock = plan_to_dock(planner, robot.pose)
    assert dock_plan.ok and dock is not None, dock_plan.reason
    for leg in dock_plan.legs:
        assert follow(leg, robot)[-1].status == "done"
    # Ends with the rear on the wall, centred on the collector, square to the wall.
    rear_x = robot.x - 0.6 * math.cos(robot.yaw)
    assert rear_x < 0.04 and abs(robot.y - 1.94) < 0.03
    # The referee, reading the drive as a trace, finds nothing either.
    head = {"arena": {}, "robot": {"length": 1.2, "width": 0.75},
            "rocks": [{"x": d.x, "y": d.y, "d": 2 * d.radius} for d in arena.obstacles[:3]],
            "craters": [{"x": d.x, "y": d.y, "d": 2 * d.radius} for d in arena.obstacles[3:]]}
    rows = [{"t": 0.1 * k, "x": x, "y": y, "yaw": math.degrees(a), "lift": 0, "bin_kg": 0,
             "delivered_kg": 0, "state": "drive"} for k, (x, y, a) in enumerate(robot.trail)]
    report = referee([json.dumps(head)] + [json.dumps(r) for r in rows])
    assert (report.collisions, report.crater_entries) == (0, 0), report.events
    start_gap = sampled_clearance(arena, start.x, start.y, start.yaw)
    for x, y, yaw in robot.trail[::3]:
        gap = sampled_clearance(arena, x, y, yaw)
        if x - 0.6 * math.cos(yaw) < 0.1:  # docking: the x = 0 wall is the target
            continue
        assert gap > min(0.0, start_gap - 0.005)


def test_a_shallow_corner_is_turned_in_place_as_the_planner_checked_it() -> None:
    # 18 deg at (1.0, 0): pure pursuit through it would lag the new heading for decimetres,
    # swinging the outer front corner wide of the sweep the planner checked.
    corner = (1.0, 0.0)
    path = Path(np.array([[0.0, 0.0], corner, [2.0, math.tan(math.radians(18.0))]]))
    robot = SkidSteer(Pose(0.0, 0.0, 0.0))
    cmds = follow(path, robot)
    turning = [k for k, c in enumerate(cmds) if c.status == "turning" and k > 5]
    assert turning, "no turn in place at the corner"
    k = turning[0]
    x, y, yaw = robot.trail[k - 1]
    assert math.hypot(x - corner[0], y - corner[1]) <= 0.015  # stopped at the corner
    assert abs(math.degrees(yaw)) < 1.0  # still facing along the first stretch
    for x, _y, yaw in robot.trail[k:]:
        if x > corner[0] + 0.05:  # past the corner: already along the second stretch
            assert abs(math.degrees(yaw) - 18.0) < 2.5
