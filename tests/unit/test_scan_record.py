"""ScanRecord's frame changes, checked against hand-worked geometry."""

from __future__ import annotations

import math

import numpy as np

from ramp.autonomy.mount import IDENTITY, Mount, lidar_pose
from ramp.autonomy.perception.records import ScanRecord


def record(ranges: list[float], angles: list[float], *, position=(0.4, 0.0, 0.7),
           rotation=IDENTITY, roll: float = 0.0, pitch: float = 0.0) -> ScanRecord:
    return ScanRecord(t=0.0, ranges=np.array(ranges), angles=np.array(angles),
                      lidar_position=position, lidar_rotation=rotation, roll=roll, pitch=pitch)


def test_a_beam_straight_ahead_lands_ahead_of_the_mount() -> None:
    pts = record([2.0], [0.0]).points_chassis()
    np.testing.assert_allclose(pts, [[2.4, 0.0, 0.7]])


def test_invalid_ranges_are_left_out() -> None:
    rec = record([1.0, math.nan, 3.0], [0.0, 0.1, math.pi / 2])
    np.testing.assert_allclose(rec.points_lidar(), [[1.0, 0.0, 0.0], [0.0, 3.0, 0.0]],
                               atol=1e-12)


def test_a_tilted_gimbal_points_the_beam_at_the_ground() -> None:
    pos, rot = lidar_pose(Mount(x=0.4, z=0.7), (0.4, 0.0, 0.7), 0.0, 30.0)
    pts = record([1.4], [0.0], position=pos, rotation=rot).points_chassis()
    # nose down 30 deg from 0.7 m: 1.4 m along the beam reaches the ground plane
    np.testing.assert_allclose(pts, [[0.4 + 1.4 * math.cos(math.radians(30)), 0.0, 0.0]],
                               atol=1e-12)


def test_a_nose_down_chassis_is_levelled_by_its_pitch() -> None:
    # chassis pitched 10 deg nose down, LIDAR level on the chassis: the beam dips 10 deg
    rec = record([2.0], [0.0], position=(0.0, 0.0, 1.0), pitch=math.radians(10))
    p = rec.points_level()[0]
    assert math.isclose(p[2], 1.0 * math.cos(math.radians(10)) - 2.0 * math.sin(math.radians(10)),
                        abs_tol=1e-12)


def test_arena_points_turn_with_the_robot_and_move_with_it() -> None:
    rec = record([1.0], [0.0], position=(0.0, 0.0, 0.5))
    p = rec.points_arena(2.0, 1.0, math.pi / 2)[0]
    np.testing.assert_allclose(p, [2.0, 2.0, 0.5], atol=1e-12)
