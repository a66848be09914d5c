"""The occupancy grid A* searches: the arena in square cells, obstacles inflated.

Each cell stores the clearance of its centre (distance to the nearest wall or obstacle
edge), and three layers follow from it:

- **blocked**: clearance < half-width + margin. The planner moves the robot's centre, and a
  centre this close would bring the footprint's side within `margin` of something.
- **lethal** (a subset): clearance < half-width. Any footprint here overlaps, whatever the yaw.
- **cost**: 1 in the open, rising linearly to 1 + `turn_cost` at the blocked edge across the
  band where the robot could not spin in place (clearance < circumradius + margin). The long,
  narrow footprint needs room to turn; this makes A* keep that room where it can without
  forbidding narrow passages it can drive straight through. The exact swept-footprint check
  (`geometry.footprint_clearance`) has the last word on every path.

Cell (i, j) covers x in [i r, (i+1) r), y in [j r, (j+1) r); arrays are indexed [i, j].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from ramp.autonomy.planning.geometry import ArenaMap, point_clearance
from ramp.autonomy.robot_model import MARTE, RobotModel

Cell = tuple[int, int]


@dataclass(frozen=True)
class PlannerConfig:
    """Grid and safety settings; the defaults are MARTE's."""

    resolution_m: float = 0.05  # 148 x 78 cells for the RMC arena
    margin_m: float = 0.10  # wanted gap between the footprint and anything, beyond contact
    min_margin_m: float = 0.05  # tried when no plan keeps `margin_m` (a tight layout)
    turn_cost: float = 3.0  # extra cost per cell at the blocked edge, tapering to 0
    waypoint_spacing_m: float = 0.10  # densified path
    robot: RobotModel = field(default=MARTE)

    def __post_init__(self) -> None:
        for name in ("resolution_m", "waypoint_spacing_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not (self.margin_m >= self.min_margin_m and self.turn_cost >= 0):
            raise ValueError("need margin_m >= min_margin_m and turn_cost >= 0")
        if self.min_margin_m < self.resolution_m:
            # The grid's line-of-sight test is exact to within a cell's half-diagonal; the
            # path check then allows half the margin, so the margin must cover the cell.
            raise ValueError(f"min_margin_m ({self.min_margin_m}) must be at least resolution_m "
                             f"({self.resolution_m})")

    @property
    def inflation_m(self) -> float:
        """Clearance below which a cell is blocked to the robot's centre."""
        return self.robot.half_width_m + self.margin_m

    @property
    def turn_room_m(self) -> float:
        """Clearance at which the robot can spin in place with the margin kept."""
        return self.robot.circumradius_m + self.margin_m

    @property
    def check_margin_m(self) -> float:
        """Gap the exact footprint check demands: half the margin (the other half is for the
        grid's discretisation and the follower's tracking error)."""
        return 0.5 * self.margin_m


@dataclass(frozen=True)
class OccupancyGrid:
    """The arena as cells, with the clearance of every cell centre and the layers above."""

    arena: ArenaMap
    config: PlannerConfig
    clearance: NDArray[np.float64]  # (nx, ny) metres
    blocked: NDArray[np.bool_]
    lethal: NDArray[np.bool_]
    cost: NDArray[np.float64]  # >= 1 per unit step

    @classmethod
    def build(cls, arena: ArenaMap, config: PlannerConfig | None = None) -> OccupancyGrid:
        config = config or PlannerConfig()
        r = config.resolution_m
        nx, ny = math.ceil(arena.length / r - 1e-9), math.ceil(arena.width / r - 1e-9)
        xs = (np.arange(nx) + 0.5) * r
        ys = (np.arange(ny) + 0.5) * r
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        clear = point_clearance(arena, gx, gy)
        return cls._from_clearance(arena, config, clear)

    @classmethod
    def _from_clearance(cls, arena: ArenaMap, config: PlannerConfig,
                        clear: NDArray[np.float64]) -> OccupancyGrid:
        inflate, room = config.inflation_m, config.turn_room_m
        band = max(room - inflate, 1e-9)
        cost = 1.0 + config.turn_cost * np.clip((room - clear) / band, 0.0, 1.0)
        return cls(arena, config, clear, clear < inflate, clear < config.robot.half_width_m,
                   cost)

    def with_penalty(self, spots: list[tuple[float, float]], radius: float,
                     extra: float) -> OccupancyGrid:
        """A copy whose cost rises by up to `extra` (at each spot, tapering to 0 at `radius`):
        steers A* away from places without closing any passage."""
        if not spots:
            return self
        gx, gy = self.cell_centres()
        cost = self.cost.copy()
        for x, y in spots:
            cost += extra * np.clip(1.0 - np.hypot(gx - x, gy - y) / radius, 0.0, 1.0)
        return replace(self, cost=cost)

    def with_poorly_seen(self, spots: NDArray[np.float64], radius: float,
                         extra: float) -> OccupancyGrid:
        """A copy whose cost rises by up to `extra` near ground the scans saw too thinly to
        trust (`spots` (k, 2), the centres of such cells; perception.coverage): `extra` at a
        spot, tapering to 0 at `radius` from the nearest one. Unlike `with_penalty` the
        spots do not add up: a wide patch costs what its nearest cell does."""
        pts = np.asarray(spots, dtype=float).reshape(-1, 2)
        if pts.shape[0] == 0 or extra <= 0.0:
            return self
        r = self.resolution
        nx, ny = self.shape
        near = np.full((nx, ny), np.inf)
        k = math.ceil(radius / r)
        for x, y in pts.tolist():
            ci, cj = math.floor(x / r), math.floor(y / r)
            i0, i1 = max(0, ci - k), min(nx, ci + k + 1)
            j0, j1 = max(0, cj - k), min(ny, cj + k + 1)
            if i0 >= i1 or j0 >= j1:
                continue
            xs = (np.arange(i0, i1) + 0.5) * r
            ys = (np.arange(j0, j1) + 0.5) * r
            d = np.hypot(xs[:, None] - x, ys[None, :] - y)
            np.minimum(near[i0:i1, j0:j1], d, out=near[i0:i1, j0:j1])
        cost = self.cost + extra * np.clip(1.0 - near / radius, 0.0, 1.0)
        return replace(self, cost=cost)

    # -- indexing ------------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.clearance.shape[0]), int(self.clearance.shape[1]))

    @property
    def resolution(self) -> float:
        return self.config.resolution_m

    def cell_centres(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        r = self.resolution
        xs = (np.arange(self.shape[0]) + 0.5) * r
        ys = (np.arange(self.shape[1]) + 0.5) * r
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        return gx, gy

    def cell_of(self, x: float, y: float) -> Cell | None:
        """The cell containing (x, y), or None outside the grid."""
        i, j = math.floor(x / self.resolution), math.floor(y / self.resolution)
        if 0 <= i < self.shape[0] and 0 <= j < self.shape[1]:
            return (i, j)
        return None

    def centre_of(self, cell: Cell) -> tuple[float, float]:
        return ((cell[0] + 0.5) * self.resolution, (cell[1] + 0.5) * self.resolution)

    def nearest_free_cell(self, x: float, y: float) -> Cell | None:
        """The free cell whose centre is nearest (x, y), or None if every cell is blocked."""
        free = np.argwhere(~self.blocked)
        if len(free) == 0:
            return None
        centres = (free + 0.5) * self.resolution
        k = int(np.argmin(np.hypot(centres[:, 0] - x, centres[:, 1] - y)))
        return (int(free[k, 0]), int(free[k, 1]))

    def is_free(self, x: float, y: float) -> bool:
        cell = self.cell_of(x, y)
        return cell is not None and not bool(self.blocked[cell])

    def line_is_free(self, p: tuple[float, float], q: tuple[float, float]) -> bool:
        """Line of sight: every point of the segment p-q lies in a free cell (sampled at a
        quarter cell)."""
        r = self.resolution
        n = max(1, math.ceil(math.hypot(q[0] - p[0], q[1] - p[1]) / (0.25 * r)))
        t = np.linspace(0.0, 1.0, n + 1)
        i = np.floor((p[0] + t * (q[0] - p[0])) / r).astype(int)
        j = np.floor((p[1] + t * (q[1] - p[1])) / r).astype(int)
        nx, ny = self.shape
        if i.min() < 0 or j.min() < 0 or i.max() >= nx or j.max() >= ny:
            return False
        return not bool(self.blocked[i, j].any())

    def line_cost(self, p: tuple[float, float], q: tuple[float, float]) -> float:
        """Cost of the straight segment p-q in the units A* uses (cells x cell cost)."""
        r = self.resolution
        length = math.hypot(q[0] - p[0], q[1] - p[1])
        n = max(1, math.ceil(length / (0.5 * r)))
        t = (np.arange(n) + 0.5) / n
        i = np.clip(np.floor((p[0] + t * (q[0] - p[0])) / r).astype(int), 0, self.shape[0] - 1)
        j = np.clip(np.floor((p[1] + t * (q[1] - p[1])) / r).astype(int), 0, self.shape[1] - 1)
        return float(self.cost[i, j].mean()) * length / r
