"""A path as the follower drives it, and the poses its footprint passes through.

A `Path` is a polyline of densified waypoints driven one way (forwards, or backwards for
docking), optionally ending with a turn in place to a final yaw. The follower turns in place
at each corner and drives the straight stretches between them; `swept_poses` lists the poses
of exactly that motion, so the planner checks the footprint the robot will really sweep.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ramp.autonomy.planning.geometry import (
    FloatArray,
    rotation_poses,
    segment_poses,
    wrap_angle,
)

CORNER_RAD = math.radians(0.5)  # direction changes below this are a straight line


@dataclass(frozen=True, eq=False)
class Path:
    """Waypoints (N, 2) in metres, driven forwards or in `reverse`; `final_yaw` (rad), when
    set, is the heading to turn to on arrival."""

    points: FloatArray
    reverse: bool = False
    final_yaw: float | None = None

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=float).reshape(-1, 2)
        if len(pts) == 0 or not np.isfinite(pts).all():
            raise ValueError("a path needs at least one finite waypoint")
        object.__setattr__(self, "points", pts)

    @property
    def length(self) -> float:
        return float(np.hypot(*np.diff(self.points, axis=0).T).sum()) if len(self.points) > 1 \
            else 0.0

    @property
    def start(self) -> tuple[float, float]:
        return (float(self.points[0, 0]), float(self.points[0, 1]))

    @property
    def end(self) -> tuple[float, float]:
        return (float(self.points[-1, 0]), float(self.points[-1, 1]))

    def corners(self) -> list[int]:
        """Indices of the waypoints where the direction changes, first and last included."""
        return corner_indices(self.points)

    def motion_yaw(self, segment_dir: float) -> float:
        """The robot's yaw while moving along a segment of direction `segment_dir`."""
        return wrap_angle(segment_dir + math.pi) if self.reverse else segment_dir


def corner_indices(points: FloatArray) -> list[int]:
    """First and last index, and every index where the polyline turns."""
    pts = _drop_repeats(points)
    n = len(pts)
    if n <= 2:
        return list(range(n))
    d = np.diff(pts, axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    turn = np.abs((np.diff(heading) + math.pi) % (2 * math.pi) - math.pi)
    return [0, *[int(k) + 1 for k in np.nonzero(turn > CORNER_RAD)[0]], n - 1]


def _drop_repeats(points: FloatArray) -> FloatArray:
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.hypot(*np.diff(points, axis=0).T) > 1e-9
    return points[keep]


def densify(vertices: Sequence[tuple[float, float]], spacing: float) -> FloatArray:
    """Waypoints no further apart than `spacing` along the polyline, every vertex kept."""
    pts = [np.asarray(vertices[0], dtype=float)[None, :]]
    for p, q in zip(vertices, vertices[1:], strict=False):
        n = max(1, math.ceil(math.hypot(q[0] - p[0], q[1] - p[1]) / spacing))
        t = np.linspace(0.0, 1.0, n + 1)[1:, None]
        pts.append(np.asarray(p, dtype=float) + t * (np.asarray(q) - np.asarray(p)))
    return np.vstack(pts)


def swept_poses(path: Path, start_yaw: float, *, step_m: float = 0.025,
                step_rad: float = math.radians(3.0)) -> FloatArray:
    """Every pose (x, y, yaw) the follower passes through: turn at the start to the first
    segment, slide along it, turn at each corner, ..., then turn to `final_yaw`."""
    pts = _drop_repeats(path.points)
    idx = corner_indices(pts)
    yaw = start_yaw
    chunks: list[FloatArray] = []
    for a, b in zip(idx, idx[1:], strict=False):
        p = (float(pts[a, 0]), float(pts[a, 1]))
        q = (float(pts[b, 0]), float(pts[b, 1]))
        seg_yaw = path.motion_yaw(math.atan2(q[1] - p[1], q[0] - p[0]))
        chunks.append(rotation_poses(p, yaw, seg_yaw, step_rad))
        chunks.append(segment_poses(p, q, seg_yaw, step_m))
        yaw = seg_yaw
    end = (float(pts[-1, 0]), float(pts[-1, 1]))
    if path.final_yaw is not None:
        chunks.append(rotation_poses(end, yaw, path.final_yaw, step_rad))
    if not chunks:
        chunks.append(np.array([[end[0], end[1], yaw]]))
    return np.vstack(chunks)


def end_yaw(path: Path, start_yaw: float) -> float:
    """The robot's yaw at the end of a path driven from `start_yaw`."""
    if path.final_yaw is not None:
        return path.final_yaw
    pts = _drop_repeats(path.points)
    if len(pts) < 2:
        return start_yaw
    d = pts[-1] - pts[-2]
    return path.motion_yaw(math.atan2(float(d[1]), float(d[0])))
