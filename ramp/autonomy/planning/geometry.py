"""Poses, obstacle discs and the exact clearance of MARTE's rectangular footprint.

The grid planner treats the robot as a disc of its half-width, which is right for driving
straight but wrong for turning: the 1.2 m x 0.75 m rectangle sweeps a disc of radius 0.71 m
when it spins. So every path is checked here, exactly, as the follower will drive it: the
rectangle slid along each segment and rotated at each vertex. Everything is vectorised over
many poses at once (numpy), since a path check is a few hundred poses.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ramp.autonomy.arena import ARENA_LENGTH_M, ARENA_WIDTH_M

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Pose:
    """A robot pose in the arena frame: centre of the footprint (m) and yaw (rad, CCW)."""

    x: float
    y: float
    yaw: float = 0.0

    @property
    def xy(self) -> tuple[float, float]:
        return (self.x, self.y)


@dataclass(frozen=True)
class Disc:
    """A round obstacle (rock or crater) by centre and radius, in metres."""

    x: float
    y: float
    radius: float

    @classmethod
    def from_diameter(cls, x: float, y: float, d: float) -> Disc:
        return cls(float(x), float(y), 0.5 * float(d))


@dataclass(frozen=True)
class ArenaMap:
    """What the planner avoids: the four walls of a rectangle and round obstacles.

    Rocks and craters are both discs to stay off (a crater is entered by any overlap).
    """

    length: float = ARENA_LENGTH_M
    width: float = ARENA_WIDTH_M
    obstacles: tuple[Disc, ...] = ()

    @classmethod
    def from_world(cls, rocks: Iterable[Mapping[str, Any]] = (),
                   craters: Iterable[Mapping[str, Any]] = (), *,
                   length: float = ARENA_LENGTH_M, width: float = ARENA_WIDTH_M) -> ArenaMap:
        """From world-file style entries `{x, y, d}` (SPEC 6.1)."""
        discs = [Disc.from_diameter(o["x"], o["y"], o["d"]) for o in (*rocks, *craters)]
        return cls(length, width, tuple(discs))

    def obstacle_array(self) -> FloatArray:
        """(M, 3) array of x, y, radius."""
        if not self.obstacles:
            return np.zeros((0, 3))
        return np.array([(d.x, d.y, d.radius) for d in self.obstacles], dtype=float)

    def describe_nearest(self, x: float, y: float) -> str:
        """Name what is nearest to a point, for a planner's error message."""
        best, name = min(
            [(x, "the x = 0 wall"), (self.length - x, f"the x = {self.length:g} wall"),
             (y, "the y = 0 wall"), (self.width - y, f"the y = {self.width:g} wall")]
            + [(math.hypot(x - d.x, y - d.y) - d.radius,
                f"the obstacle at ({d.x:.2f}, {d.y:.2f}), d {2 * d.radius:.2f} m")
               for d in self.obstacles])
        return f"{name} ({best:.2f} m away)"


def point_clearance(arena: ArenaMap, xs: FloatArray, ys: FloatArray) -> FloatArray:
    """Distance from each point to the nearest wall or obstacle edge (negative inside one)."""
    clear = np.minimum(np.minimum(xs, arena.length - xs), np.minimum(ys, arena.width - ys))
    for d in arena.obstacles:
        clear = np.minimum(clear, np.hypot(xs - d.x, ys - d.y) - d.radius)
    return clear


def footprint_clearance(arena: ArenaMap, poses: FloatArray, half_length: float,
                        half_width: float, *, x0_wall: bool = True) -> FloatArray:
    """Clearance (m) of the rectangle at each pose (N, 3: x, y, yaw) from walls and obstacles.

    Negative is overlap. `x0_wall=False` leaves out the x = 0 wall, for the docking leg that
    ends with the rear against it on purpose.
    """
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    x, y, yaw = poses[:, 0], poses[:, 1], poses[:, 2]
    c, s = np.abs(np.cos(yaw)), np.abs(np.sin(yaw))
    ext_x = half_length * c + half_width * s  # half extent of the rectangle along x
    ext_y = half_length * s + half_width * c
    walls = [arena.length - (x + ext_x), y - ext_y, arena.width - (y + ext_y)]
    if x0_wall:
        walls.append(x - ext_x)
    clear = np.minimum.reduce(walls)
    if arena.obstacles:
        obs = arena.obstacle_array()
        dx = obs[None, :, 0] - x[:, None]
        dy = obs[None, :, 1] - y[:, None]
        cy, sy = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
        u = np.abs(dx * cy + dy * sy) - half_length  # disc centre in the robot frame, minus
        v = np.abs(-dx * sy + dy * cy) - half_width  # the half extents
        outside = np.hypot(np.maximum(u, 0.0), np.maximum(v, 0.0))
        inside = np.minimum(np.maximum(u, v), 0.0)  # <= 0 when the centre is inside
        clear = np.minimum(clear, (outside + inside - obs[None, :, 2]).min(axis=1))
    return clear


def wrap_angle(a: float) -> float:
    """Angle wrapped into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def segment_poses(p: tuple[float, float], q: tuple[float, float], yaw: float,
                  step: float) -> FloatArray:
    """Poses sliding from p to q at a fixed yaw, no further apart than `step`."""
    n = max(1, math.ceil(math.hypot(q[0] - p[0], q[1] - p[1]) / step))
    t = np.linspace(0.0, 1.0, n + 1)
    return np.column_stack([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]),
                            np.full_like(t, yaw)])


def rotation_poses(p: tuple[float, float], yaw0: float, yaw1: float,
                   step: float) -> FloatArray:
    """Poses turning in place at p from yaw0 to yaw1 the short way, `step` rad apart at most."""
    delta = wrap_angle(yaw1 - yaw0)
    n = max(1, math.ceil(abs(delta) / step))
    t = np.linspace(0.0, 1.0, n + 1)
    return np.column_stack([np.full_like(t, p[0]), np.full_like(t, p[1]), yaw0 + t * delta])
