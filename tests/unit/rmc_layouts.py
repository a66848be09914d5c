"""Random RMC layouts and start poses by SPEC 6.1's rules, and an independent footprint check,
for the planning, follower and referee tests (written from the SPEC, not from the planner)."""

from __future__ import annotations

import math
import random

import numpy as np

from ramp.autonomy.planning import ArenaMap, Disc, Pose

LENGTH, WIDTH = 7.38, 3.88
HALF_L, HALF_W = 0.6, 0.375


def random_layout(rng: random.Random) -> ArenaMap:
    """Three rocks (d 0.10-0.30) and two craters (d 0.15-0.30), wholly inside the obstacle
    region 1.5 <= x < 4.44, not overlapping."""
    discs: list[Disc] = []
    for count, lo, hi in ((3, 0.10, 0.30), (2, 0.15, 0.30)):
        placed = 0
        while placed < count:
            r = rng.uniform(lo, hi) / 2
            x, y = rng.uniform(1.5 + r, 4.44 - r), rng.uniform(r, WIDTH - r)
            if any(math.hypot(x - o.x, y - o.y) < r + o.radius for o in discs):
                continue
            discs.append(Disc(x, y, r))
            placed += 1
    return ArenaMap(LENGTH, WIDTH, tuple(discs))


def random_start(rng: random.Random, box: str, heading_deg: int) -> Pose:
    """Box default pose perturbed by up to +-10 deg and +-0.2 m, footprint inside the box."""
    yaw = math.radians(heading_deg + rng.uniform(-10, 10))
    y_lo, y_hi = (1.94, WIDTH) if box == "left" else (0.0, 1.94)
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    ext_x, ext_y = HALF_L * c + HALF_W * s, HALF_L * s + HALF_W * c
    for _ in range(1000):
        x = 0.75 + rng.uniform(-0.2, 0.2)
        y = 0.5 * (y_lo + y_hi) + rng.uniform(-0.2, 0.2)
        if x - ext_x >= 0 and x + ext_x < 1.5 and y - ext_y >= y_lo and y + ext_y < y_hi:
            return Pose(x, y, yaw)
    raise AssertionError("no start pose fits the box")


def footprint_points(x: float, y: float, yaw: float, step: float = 0.025) -> np.ndarray:
    """Points covering the 1.2 m x 0.75 m rectangle (boundary and interior), world frame."""
    us = np.linspace(-HALF_L, HALF_L, int(2 * HALF_L / step) + 1)
    vs = np.linspace(-HALF_W, HALF_W, int(2 * HALF_W / step) + 1)
    gu, gv = np.meshgrid(us, vs)
    c, s = math.cos(yaw), math.sin(yaw)
    return np.column_stack([x + c * gu.ravel() - s * gv.ravel(),
                            y + s * gu.ravel() + c * gv.ravel()])


def sampled_clearance(arena: ArenaMap, x: float, y: float, yaw: float) -> float:
    """Smallest gap between the sampled footprint and any wall or disc (negative: overlap)."""
    pts = footprint_points(x, y, yaw)
    gap = min(pts[:, 0].min(), LENGTH - pts[:, 0].max(), pts[:, 1].min(),
              WIDTH - pts[:, 1].max())
    for d in arena.obstacles:
        gap = min(gap, float(np.hypot(pts[:, 0] - d.x, pts[:, 1] - d.y).min()) - d.radius)
    return float(gap)
