"""Ground the scans saw too thinly to trust, and the planner keeping off it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ramp.autonomy.executive.scan import COVERAGE_NOTE, build_map
from ramp.autonomy.perception.coverage import MIN_RETURNS, GroundCoverage
from ramp.autonomy.perception.pipeline import Obstacle
from ramp.autonomy.planning import ArenaMap, Planner, Pose
from ramp.autonomy.planning.grid import OccupancyGrid
from ramp.autonomy.planning.path import swept_poses
from ramp.statemachine import MissionContext


def _cell_points(x: float, y: float, n: int, z: float = 0.0) -> np.ndarray:
    return np.array([[x, y, z]] * n)


def test_returns_are_counted_per_cell_of_the_obstacle_region_in_the_ground_band() -> None:
    cov = GroundCoverage.empty()
    assert cov.counts.shape == (30, 39)  # 1.5..4.44 m by 0..3.88 m in 10 cm cells
    pts = np.vstack([_cell_points(1.55, 0.05, 3), _cell_points(2.01, 1.0, 2, z=0.25),
                     _cell_points(2.01, 1.0, 5, z=0.6),  # above the band: a wall, a person
                     _cell_points(2.01, 1.0, 4, z=-0.5),  # below it: no floor is that deep
                     _cell_points(2.21, 1.0, 1, z=-0.25),  # in a crater
                     _cell_points(1.2, 1.0, 9),  # the start region: not counted
                     _cell_points(4.5, 1.0, 9)])  # the digging region: not counted
    after = cov.add(pts)
    assert after.counts[0, 0] == 3 and after.counts[5, 10] == 2 and after.counts[7, 10] == 1
    assert after.counts.sum() == 6
    assert cov.counts.sum() == 0  # add makes a copy


def test_a_cell_with_fewer_returns_than_the_threshold_is_poorly_seen() -> None:
    cov = GroundCoverage.empty().add(np.vstack([
        _cell_points(1.55, 0.05, MIN_RETURNS), _cell_points(1.65, 0.05, MIN_RETURNS - 1)]))
    poor = cov.poorly_seen()
    assert not poor[0, 0] and poor[1, 0]
    centres = cov.poorly_seen_centres()
    assert len(centres) == poor.size - 1
    assert [1.65, 0.05] in np.round(centres, 6).tolist()
    assert [1.55, 0.05] not in np.round(centres, 6).tolist()


def test_the_cost_rises_near_poorly_seen_ground_without_adding_up_or_closing_anything() -> None:
    grid = OccupancyGrid.build(ArenaMap())
    assert grid.with_poorly_seen(np.zeros((0, 2)), 0.7, 2.0) is grid
    one = grid.with_poorly_seen(np.array([[3.0, 2.0]]), 0.7, 2.0)
    many = grid.with_poorly_seen(np.array([[3.0, 2.0], [3.05, 2.0], [2.95, 2.0]]), 0.7, 2.0)
    i, j = grid.cell_of(3.0, 2.0)  # type: ignore[misc]
    assert one.cost[i, j] == pytest.approx(grid.cost[i, j] + 2.0 * (1 - math.hypot(
        0.025, 0.025) / 0.7))
    far = grid.cell_of(3.0, 2.8)
    assert far is not None and one.cost[far] == grid.cost[far]
    assert many.cost.max() <= grid.cost.max() + 2.0  # the nearest spot counts, not the sum
    assert (one.blocked == grid.blocked).all()


def test_plans_keep_off_poorly_seen_ground_where_the_arena_leaves_room() -> None:
    # A thinly seen strip along the y = 0 wall: the straight way runs along it.
    strip = np.array([[x, y] for x in np.arange(1.55, 4.44, 0.1) for y in (0.05, 0.15, 0.25)])
    start, goal = Pose(1.0, 0.8, 0.0), (5.0, 0.8)
    blind = Planner(ArenaMap()).plan(start, goal)
    careful = Planner(ArenaMap(), poorly_seen=strip).plan(start, goal)
    assert blind.ok and careful.ok

    def y_mid(result: object) -> float:  # where the robot's centre crosses x = 3
        poses = np.vstack([swept_poses(leg, start.yaw) for leg in result.legs])  # type: ignore[attr-defined]
        return float(poses[np.argmin(np.abs(poses[:, 0] - 3.0)), 1])

    assert y_mid(blind) == pytest.approx(0.8)
    assert y_mid(careful) > 0.25 + 0.7  # the strip's edge plus the circumradius
    assert careful.length_m < blind.length_m + 1.0  # a detour, not a tour


def test_the_map_carries_the_poorly_seen_ground_into_the_planner() -> None:
    ctx = MissionContext()
    found = [Obstacle("rock", 2.5, 2.0, 0.2)]
    build_map(ctx, found, 0.03, 0.10)
    assert ctx.planner is not None and len(ctx.planner.poorly_seen) == 0
    ctx.notes[COVERAGE_NOTE] = GroundCoverage.empty()  # nothing seen: all of it is thin
    build_map(ctx, found, 0.03, 0.10)
    assert len(ctx.planner.poorly_seen) == 30 * 39
