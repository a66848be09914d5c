"""How densely the 3D scans sampled the floor of the obstacle region: returns per 10 cm cell.

The detector finds a crater from the returns on and around it. Far to the side of a sweep,
at a grazing angle, the scan lines thin out and a small crater can be crossed by too few of
them to be found: seed 12's `gyro-drift` run drove past one such crater 1.5 cm away, with
7-11 returns in each cell around it where the ground the same sweep saw well had 16-60. A
cell of the obstacle region (SPEC 6.1: the only place rocks and craters may be) with fewer
than `MIN_RETURNS` returns in the ground band is *poorly seen*; the planner keeps the
footprint off such cells where the layout lets it, as it keeps room to turn
(`OccupancyGrid.with_poorly_seen`). Rocks block the floor behind them, so their shadows are
poorly seen too. Each closer look adds its returns.

The threshold belongs to the sweep it was measured on (`sweep_spacing_m` 4 cm, these 10 cm
cells): a config that spaces the ground lines wider should lower it. Cells along a wall
count the wall's own low returns, so they never read as poorly seen; the planner keeps the
footprint off the walls anyway.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ramp.autonomy import arena

FloatArray = NDArray[np.float64]

CELL_M = 0.10  # the detector's ground-model cell
#: Returns a cell of 10 x 10 cm needs to count as seen: below what the sweep's well-seen
#: ground has (16-60 at 1-3 m), above what the missed crater's neighbourhood had (7-11).
MIN_RETURNS = 12
#: |z| of the returns counted: the ground, and rocks and craters (within 0.3 m of it).
BAND_M = 0.3


@dataclass(frozen=True, eq=False)  # an array inside: no field-wise == or hash
class GroundCoverage:
    """Returns in the ground band per `cell_m` cell of the obstacle region, indexed [i, j]
    for x in [x0 + i cell, x0 + (i + 1) cell), y in [j cell, (j + 1) cell)."""

    counts: NDArray[np.int64]
    cell_m: float = CELL_M
    x0: float = arena.START_END_X_M

    @classmethod
    def empty(cls, cell_m: float = CELL_M) -> GroundCoverage:
        nx = math.ceil((arena.OBSTACLE_END_X_M - arena.START_END_X_M) / cell_m - 1e-9)
        ny = math.ceil(arena.ARENA_WIDTH_M / cell_m - 1e-9)
        return cls(np.zeros((nx, ny), dtype=np.int64), cell_m)

    def add(self, points: FloatArray) -> GroundCoverage:
        """A copy with the returns `points` (n, 3) arena frame counted in."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        p = p[np.abs(p[:, 2]) <= BAND_M]
        i = np.floor((p[:, 0] - self.x0) / self.cell_m)
        j = np.floor(p[:, 1] / self.cell_m)
        nx, ny = self.counts.shape
        inside = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
        counts = self.counts.copy()
        np.add.at(counts, (i[inside].astype(np.intp), j[inside].astype(np.intp)), 1)
        return GroundCoverage(counts, self.cell_m, self.x0)

    def poorly_seen(self, min_returns: int = MIN_RETURNS) -> NDArray[np.bool_]:
        """(nx, ny) True where a cell has fewer than `min_returns` returns."""
        return np.asarray(self.counts < min_returns)

    def poorly_seen_centres(self, min_returns: int = MIN_RETURNS) -> FloatArray:
        """(k, 2) x, y of the centres of the cells with fewer than `min_returns` returns."""
        idx = np.argwhere(self.poorly_seen(min_returns))
        out: FloatArray = np.column_stack((self.x0 + (idx[:, 0] + 0.5) * self.cell_m,
                                           (idx[:, 1] + 0.5) * self.cell_m)).astype(float)
        return out
