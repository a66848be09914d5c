"""The perception's calls (`pipeline.py`) on scans of the simulated arena, without the rig:
scans fused beam by beam, the sweep planned from any pose, level found on the floor, the
tracker following odometry. The whole chain on the rig is `test_perception_chain.py`."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from firmware_like.lidar_view import LidarView
from firmware_like.marte import MarteWorld
from ramp.autonomy.mount import angle_between
from ramp.autonomy.odometry import Odometry
from ramp.autonomy.perception import pipeline
from ramp.autonomy.perception.ahrs import up_in_chassis
from ramp.autonomy.perception.records import ScanRecord
from ramp.simulation.rig import load_autonomy_config
from tests.unit.localizer_scenes import errors, shoot

CONFIG = load_autonomy_config()


def scans(world: MarteWorld, n: int = 5, **kw: float) -> list[ScanRecord]:
    view = LidarView.of(world)
    return [shoot(world, view, t=0.025 * k, **kw).record for k in range(n)]


def test_fused_scans_take_each_beams_median_and_drop_a_lone_echo() -> None:
    world = MarteWorld.seeded(4, "left", 0)
    records = scans(world, 5)
    lone = records[2].ranges.copy()
    lone[100] = 0.5  # a dust echo in one scan
    records[2] = replace(records[2], ranges=lone)
    gone = records[3].ranges.copy()
    gone[200] = np.nan
    records[3] = replace(records[3], ranges=gone)
    fused, n = pipeline.fuse_scans(records)
    assert n == 5
    stack = np.stack([r.ranges for r in records])
    assert fused.ranges[100] == pytest.approx(float(np.median(stack[[0, 1, 3, 4], 100])),
                                              abs=0.011)
    assert math.isfinite(fused.ranges[200])  # missing in one scan of five: still seen
    assert abs(float(np.nanmedian(fused.ranges - records[0].ranges))) < 0.005
    # a record from another view (tilted) is not fused with the last one
    tilted = shoot(world, LidarView.of(world), tilt=math.radians(10.0)).record
    assert pipeline.fuse_scans([tilted, *records])[1] == 5
    assert pipeline.fuse_scans([*records, tilted])[1] == 1


def test_localize_gives_the_pose_its_covariance_and_the_mirror_as_a_candidate() -> None:
    world = MarteWorld.seeded(6, "right", 90)
    res = pipeline.localize(scans(world), hint="right")
    assert not res.lost and res.pose is not None and res.reason == ""
    assert res.pose.confidence >= pipeline.HIGH_CONFIDENCE
    d, dyaw = errors(res.pose, world.chassis_pose())  # type: ignore[arg-type]
    assert d < 0.02 and dyaw < 0.5
    assert res.covariance is not None and res.covariance.shape == (3, 3) and res.scans == 5
    mirror = [c for c in res.candidates
              if math.hypot(c.x - (7.38 - world.x), c.y - (3.88 - world.y)) < 0.05]
    assert mirror and mirror[0].confidence < 0.01
    without = pipeline.localize(scans(world))  # no hint, no yaw: the twins cannot be told
    assert without.lost and without.pose is None and "symmetric" in without.reason
    with pytest.raises(ValueError, match="start box"):
        pipeline.localize(scans(world), hint="middle")


def test_the_sweep_covers_the_obstacle_region_from_the_start_and_stops_short_of_walls() -> None:
    start = pipeline.plan_scan(CONFIG, pipeline.PoseEstimate(0.9, 1.94, 0.0))
    assert start is not None and start.pan_deg == 0.0
    assert start.far_m == pytest.approx(4.44 + 0.3 - 0.9)
    assert 0.55 < start.blind_m < 0.65  # 75 deg down: the ground 0.6 m ahead of the centre
    assert 75 <= start.scans <= 90 and start.duration_s < 14.0
    across = pipeline.plan_scan(CONFIG, pipeline.PoseEstimate(3.0, 0.6, math.pi / 2))
    assert across is not None and across.far_m == pytest.approx(3.88 - 0.6 - 0.15)
    assert pipeline.plan_scan(CONFIG, pipeline.PoseEstimate(3.0, 3.3, math.pi / 2)) is None
    lost = pipeline.plan_scan(CONFIG, ahead_m=2.0, pan_deg=90.0)
    assert lost is not None and lost.far_m == pytest.approx(1.85) and lost.pan_deg == 90.0


def test_free_ahead_measures_from_the_footprint_centre_along_a_bearing() -> None:
    world = MarteWorld.seeded(2)
    world.place(3.0, 1.0, 90.0)  # facing +y: the left wall 2.88 m ahead, the far wall right
    records = scans(world, 3)
    assert pipeline.free_ahead(records) == pytest.approx(2.88, abs=0.05)
    assert pipeline.free_ahead(records, -90.0) == pytest.approx(7.38 - 3.0, abs=0.05)
    assert pipeline.free_ahead(records, 90.0) == pytest.approx(3.0, abs=0.05)


def sweep_records(world: MarteWorld, roll_error: float, pitch_error: float,
                  plan_tilts: list[float]) -> list[ScanRecord]:
    view = LidarView.of(world)
    c = world.chassis_pose()
    pitch_b = c.pitch + pitch_error
    return [shoot(world, view, roll_error=roll_error, pitch_error=pitch_error,
                  tilt=math.radians(t) - pitch_b).record for t in plan_tilts]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_floor_says_where_level_is_when_the_imu_has_moved(seed: int) -> None:
    world = MarteWorld.seeded(seed)
    world.place(0.9, 1.94, 0.0)
    plan = pipeline.plan_scan(CONFIG, pipeline.PoseEstimate(0.9, 1.94, 0.0))
    assert plan is not None
    tilts = list(plan.tilts_deg[::4])
    rng = np.random.default_rng(seed)
    error = math.radians(rng.uniform(4, 8))
    axis = rng.uniform(0, 2 * math.pi)
    records = sweep_records(world, error * math.cos(axis), error * math.sin(axis), tilts)
    hint = pipeline.level_from_floor(records)
    assert hint is not None and hint.weight == 1.0
    truth = up_in_chassis(world.roll, world.pitch)
    assert math.degrees(angle_between(up_in_chassis(hint.roll, hint.pitch), truth)) < 0.5
    # and with the right attitude it agrees with it, far inside FLOOR_ADOPT_DEG
    hint = pipeline.level_from_floor(sweep_records(world, 0.0, 0.0, tilts))
    assert hint is not None
    off = math.degrees(angle_between(up_in_chassis(hint.roll, hint.pitch), truth))
    assert off < pipeline.FLOOR_ADOPT_DEG / 2


def test_a_strip_of_floor_before_a_wall_does_not_pretend_to_know_level() -> None:
    world = MarteWorld.seeded(3)
    world.place(6.5, 1.94, 0.0)  # the far wall 0.9 m ahead
    assert pipeline.level_from_floor(sweep_records(world, 0.0, 0.0, [60, 65, 70, 75])) is None
    assert pipeline.level_from_floor([]) is None


def test_the_tracker_follows_odometry_and_the_walls_correct_it() -> None:
    world = MarteWorld.seeded(9, "left", 0)
    odometry = Odometry(now=0.0)
    tracker = pipeline.Tracker(odometry=odometry)
    first = tracker.initialise(scans(world, 3), hint="left")
    assert not first.lost and tracker.t == pytest.approx(0.025)
    start = tracker.pose
    assert start is not None and start.confidence >= pipeline.HIGH_CONFIDENCE
    odometry.wheels(1.0, 40.0, 40.0)  # straight ahead for a while
    odometry.stop(4.0)
    odometry.advance(6.0)
    dx, dy, dyaw = odometry.relative(0.025, 6.0)
    world.place(world.x + dx * math.cos(world.yaw) - dy * math.sin(world.yaw),
                world.y + dx * math.sin(world.yaw) + dy * math.cos(world.yaw),
                math.degrees(world.yaw + dyaw))
    tracker.advance(6.0)
    moved = tracker.pose
    assert moved is not None and math.hypot(moved.x - start.x, moved.y - start.y) > 0.3
    later = [replace(r, t=6.0 + r.t, yaw=world.yaw + math.radians(5)) for r in scans(world, 3)]
    res = tracker.update(later)
    assert not res.lost and res.pose is not None
    d, dyaw_err = errors(res.pose, world.chassis_pose())  # type: ignore[arg-type]
    assert d < 0.03 and dyaw_err < 0.5
    # carried off 1 m with no odometry: lost, dead-reckoned with confidence 0, then found
    world.place(world.x, world.y - 1.0, math.degrees(world.yaw))
    kidnapped = [replace(r, t=7.0 + r.t, yaw=world.yaw) for r in scans(world, 3)]
    res = tracker.update(kidnapped)
    assert res.lost and "odometry" in res.reason and tracker.lost
    assert tracker.pose is not None and tracker.pose.confidence == 0.0
    res = tracker.relocalize(kidnapped)
    assert not res.lost and errors(res.pose, world.chassis_pose())[0] < 0.03  # type: ignore
