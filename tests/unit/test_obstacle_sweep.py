"""The 3D scan's tilt plan and the merge of its records into one cloud, against geometry
worked by hand."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ramp.autonomy.config import load_config
from ramp.autonomy.mount import IDENTITY, Mount, lidar_pose
from ramp.autonomy.perception.cloud import (
    ground_ahead,
    merge,
    move_time,
    plan_sweep,
    region_distances,
    sweep_from_config,
    tilt_for,
)
from ramp.autonomy.perception.records import ScanRecord

SIM_MOUNT = Mount(0.40, 0.0, 0.70)  # firmware_like's scanner: on its tilt axis
SIM_PIVOT = (0.40, 0.0, 0.70)
YAML_MOUNT = Mount(0.45, 0.0, 0.61)  # autonomy.yaml: 6 cm above the tilt axis
YAML_PIVOT = (0.45, 0.0, 0.55)
REPO = Path(__file__).resolve().parents[2]


def test_a_short_move_is_a_triangle_and_a_long_one_cruises() -> None:
    # 60 deg/s, 360 deg/s^2: the cruise speed is reached after 10 deg of travel (5 + 5)
    assert move_time(1.0, 60.0, 360.0) == pytest.approx(2.0 * math.sqrt(1.0 / 360.0))
    assert move_time(-1.0, 60.0, 360.0) == move_time(1.0, 60.0, 360.0)
    assert move_time(45.0, 60.0, 360.0) == pytest.approx(45.0 / 60.0 + 60.0 / 360.0)
    assert move_time(10.0, 60.0, 360.0) == pytest.approx(2.0 * math.sqrt(10.0 / 360.0))
    assert move_time(0.0, 60.0, 360.0) == 0.0


@pytest.mark.parametrize(("mount", "pivot"), [(SIM_MOUNT, SIM_PIVOT), (YAML_MOUNT, YAML_PIVOT)])
def test_the_tilt_for_a_distance_lays_the_beam_on_the_ground_there(mount: Mount,
                                                                    pivot: tuple) -> None:
    for distance in (0.7, 1.5, 2.5, 3.84):
        tilt = tilt_for(mount, pivot, distance)
        assert ground_ahead(mount, pivot, tilt) == pytest.approx(distance, abs=1e-6)
        # and by the record's own geometry: the beam straight ahead ends on z = 0 there
        pos, rot = lidar_pose(mount, pivot, 0.0, tilt)
        t = pos[2] / -rot[2][0]
        assert pos[0] + t * rot[0][0] == pytest.approx(distance, abs=1e-6)


def test_on_the_sim_mount_a_45_degree_tilt_meets_the_ground_0_7_m_ahead_of_the_scanner() -> None:
    assert ground_ahead(SIM_MOUNT, SIM_PIVOT, 45.0) == pytest.approx(0.40 + 0.70)
    assert ground_ahead(SIM_MOUNT, SIM_PIVOT, 0.0) == math.inf
    # panned 90 deg left, the line runs along the robot's left side instead
    assert ground_ahead(SIM_MOUNT, SIM_PIVOT, 45.0, pan_deg=90.0) == pytest.approx(0.70)


def test_the_plan_spaces_its_ground_lines_evenly_far_first() -> None:
    plan = plan_sweep(SIM_MOUNT, SIM_PIVOT, near_m=0.6, far_m=3.84, spacing_m=0.04,
                      tilt_max_deg=75.0)
    lines = [ground_ahead(SIM_MOUNT, SIM_PIVOT, t) for t in plan.tilts_deg]
    assert lines[0] == pytest.approx(3.84, abs=2e-3) and lines[-1] == pytest.approx(0.6, abs=2e-3)
    gaps = -np.diff(lines)
    assert np.all(gaps > 0.0) and np.allclose(gaps, plan.spacing_m, atol=2e-3)
    assert plan.spacing_m <= 0.04 and plan.scans == len(lines) == 82
    assert plan.blind_m < 0.6 and plan.near_m == pytest.approx(0.6)
    assert list(plan.tilts_deg) == sorted(plan.tilts_deg)  # tilting further down each time


def test_the_tilt_limit_leaves_the_ground_close_ahead_unseen_and_the_plan_says_so() -> None:
    plan = plan_sweep(SIM_MOUNT, SIM_PIVOT, near_m=0.6, far_m=3.84, tilt_max_deg=45.0)
    assert plan.blind_m == pytest.approx(1.10)
    assert plan.near_m == pytest.approx(1.10) and plan.tilts_deg[-1] == 45.0
    with pytest.raises(ValueError, match="from 1.10 m ahead only"):
        plan_sweep(SIM_MOUNT, SIM_PIVOT, near_m=0.5, far_m=1.0, tilt_max_deg=45.0)


def test_the_duration_adds_every_move_and_two_scan_periods_a_tilt() -> None:
    plan = plan_sweep(SIM_MOUNT, SIM_PIVOT, near_m=1.5, far_m=3.0, spacing_m=0.25,
                      velocity_dps=60.0, acceleration_dps2=360.0)
    path = [0.0, *plan.tilts_deg, 0.0]
    moving = sum(move_time(b - a, 60.0, 360.0) for a, b in zip(path, path[1:], strict=False))
    assert plan.move_s == pytest.approx(moving)
    assert plan.scanning_s == pytest.approx(2 * 0.025 * plan.scans)
    assert plan.duration_s == pytest.approx(plan.move_s + plan.scanning_s)


def test_the_mission_sweep_from_the_start_region_takes_about_thirteen_seconds() -> None:
    """From the start region (robot at x = 0.9, facing +x) over the obstacle region and
    0.3 m beyond, lines every 4 cm, with autonomy.yaml's tilt servo (60 deg/s, 360 deg/s^2)
    and a 75 deg travel: 82 scans, 8.5 s of moves (small steps are acceleration-bound) and
    4.1 s of scans. A livelier servo setting (2000 deg/s^2) saves a third."""
    plan = plan_sweep(SIM_MOUNT, SIM_PIVOT, near_m=0.6, far_m=4.74 - 0.9, tilt_max_deg=75.0)
    assert plan.scans == 82
    assert 12.0 < plan.duration_s < 13.0
    brisk = plan_sweep(SIM_MOUNT, SIM_PIVOT, near_m=0.6, far_m=4.74 - 0.9, tilt_max_deg=75.0,
                       acceleration_dps2=2000.0)
    assert brisk.duration_s < 0.7 * plan.duration_s


@pytest.mark.parametrize("bad", [
    {"near_m": 2.0, "far_m": 1.0}, {"near_m": 0.5, "far_m": 3.0, "spacing_m": 0.0},
    {"near_m": 0.5, "far_m": 3.0, "tilt_min_deg": 10.0, "tilt_max_deg": 10.0},
    {"near_m": 0.5, "far_m": math.nan}, {"near_m": 0.5, "far_m": 3.0, "velocity_dps": -1.0},
])
def test_a_plan_that_cannot_be_is_refused(bad: dict) -> None:
    with pytest.raises(ValueError):
        plan_sweep(SIM_MOUNT, SIM_PIVOT, **bad)


def _record(ranges: list[float], angles: list[float], *, tilt: float = 0.0,
            roll: float = 0.0, pitch: float = 0.0) -> ScanRecord:
    pos, rot = lidar_pose(SIM_MOUNT, SIM_PIVOT, 0.0, tilt)
    return ScanRecord(t=0.0, ranges=np.array(ranges), angles=np.array(angles),
                      lidar_position=pos, lidar_rotation=rot, roll=roll, pitch=pitch,
                      tilt_deg=tilt)


def test_merge_places_each_return_in_the_arena_and_remembers_its_scan_and_beam() -> None:
    down = _record([math.nan, 0.7 * math.sqrt(2.0), 5.0], [-0.1, 0.0, 0.1], tilt=45.0)
    level = _record([2.0], [0.0])
    cloud = merge([down, level], 1.0, 2.0, math.pi / 2)  # facing +y
    assert len(cloud) == 3
    np.testing.assert_array_equal(cloud.scan, [0, 0, 1])
    np.testing.assert_array_equal(cloud.beam, [1, 2, 0])  # the NaN beam is left out
    # 45 deg down from 0.7 m: the ground 0.7 m ahead of the scanner, i.e. 1.1 m ahead of
    # the footprint centre, which faces +y
    np.testing.assert_allclose(cloud.points[0], [1.0, 3.1, 0.0], atol=1e-12)
    np.testing.assert_allclose(cloud.points[2], [1.0, 2.0 + 0.4 + 2.0, 0.7], atol=1e-12)
    np.testing.assert_allclose(cloud.origins, [[1.0, 2.4, 0.7], [1.0, 2.4, 0.7]], atol=1e-12)
    np.testing.assert_allclose(cloud.ranges(), [0.7 * math.sqrt(2.0), 5.0, 2.0])
    np.testing.assert_allclose(np.linalg.norm(cloud.directions(), axis=1), 1.0)
    np.testing.assert_array_equal(cloud.tilts_deg, [45.0, 0.0])
    for i, rec in enumerate((down, level)):  # the same frames as ScanRecord's own
        np.testing.assert_allclose(cloud.points[cloud.scan == i],
                                   rec.points_arena(1.0, 2.0, math.pi / 2), atol=1e-12)


def test_merge_uses_each_records_own_roll_and_pitch() -> None:
    # the chassis pitched 5 deg nose down: a level scanner's beam dips 5 deg
    rec = _record([3.0], [0.0], pitch=math.radians(5.0))
    cloud = merge([rec], 0.0, 0.0, 0.0, ground_z=0.1)
    p = cloud.points[0]
    assert p[2] == pytest.approx(0.1 + 0.7 * math.cos(math.radians(5.0)) - (
        0.4 + 3.0) * math.sin(math.radians(5.0)))
    assert cloud.ground_z == 0.1 and cloud.pose == (0.0, 0.0, 0.0)


def test_merging_nothing_gives_an_empty_cloud() -> None:
    empty = merge([], 1.0, 1.0, 0.0)
    assert len(empty) == 0 and empty.points.shape == (0, 3)
    blank = merge([ScanRecord(0.0, np.array([math.nan]), np.array([0.0]), (0.0, 0.0, 0.5),
                              IDENTITY, 0.0, 0.0)], 1.0, 1.0, 0.0)
    assert len(blank) == 0 and blank.origins.shape == (1, 3)


def test_the_region_distances_cover_the_obstacle_region_and_a_margin_beyond() -> None:
    assert region_distances(0.9) == pytest.approx((0.6, 4.44 + 0.3 - 0.9))
    assert region_distances(2.3, far_margin_m=0.0) == pytest.approx((0.05, 4.44 - 2.3))
    with pytest.raises(ValueError, match="nothing to scan"):
        region_distances(5.0)


def test_autonomy_yaml_gives_the_plan_its_mount_pivot_and_tilt_servo() -> None:
    config = load_config(REPO / "autonomy.yaml")
    plan = sweep_from_config(config, *region_distances(0.9))
    tilt = config.gimbal.tilt
    assert max(plan.tilts_deg) <= tilt.max_deg and min(plan.tilts_deg) >= tilt.min_deg
    assert plan.blind_m == pytest.approx(ground_ahead(config.lidar.mount, config.gimbal.pivot,
                                                      tilt.max_deg))
    same = plan_sweep(config.lidar.mount, config.gimbal.pivot, near_m=0.6, far_m=4.74 - 0.9,
                      tilt_min_deg=tilt.min_deg, tilt_max_deg=tilt.max_deg,
                      velocity_dps=tilt.velocity_dps, acceleration_dps2=tilt.acceleration_dps2)
    assert plan == same
