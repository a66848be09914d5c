"""`planner`: A* on the full RMC arena grid, beside a breadth-first search on the same grid.

Random layouts by SPEC 6.1's rules (three rocks, two craters in the obstacle region), one
query each from the start region to the far end of the digging region, on the planner's
grid (5 cm cells, 148 x 78). Per query: A* (8-connected, octile heuristic, turn costs) and,
as the baseline in the same run, a plain breadth-first search between the same cells
(unit steps, no costs, no heuristic: the least work that still answers "is there a way").
Also the whole `Planner.plan` (A*, shortcutting, exact footprint checks, any manoeuvres to
get clear), the grid build, and A* across an empty arena corner to corner.
"""

from __future__ import annotations

import math
import random
import time
from pathlib import Path
from typing import Any

from bench.common import Settings, compare, progress, summary
from ramp.autonomy.planning import (
    ArenaMap,
    Disc,
    OccupancyGrid,
    Planner,
    Pose,
    astar,
    bfs_steps,
)

QUERIES = {"full": 40, "quick": 12, "smoke": 2}


def _layout(rng: random.Random) -> ArenaMap:
    discs: list[Disc] = []
    for count, lo, hi in ((3, 0.10, 0.30), (2, 0.15, 0.30)):
        while count:
            r = rng.uniform(lo, hi) / 2
            x, y = rng.uniform(1.5 + r, 4.44 - r), rng.uniform(r, 3.88 - r)
            if all(math.hypot(x - d.x, y - d.y) >= r + d.radius for d in discs):
                discs.append(Disc(x, y, r))
                count -= 1
    return ArenaMap(obstacles=tuple(discs))


def _ms(fn: Any, *args: Any) -> tuple[float, Any]:
    t0 = time.perf_counter()
    out = fn(*args)
    return (time.perf_counter() - t0) * 1e3, out


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    rng = random.Random(2014)
    n = QUERIES[settings.profile]
    astar_ms, bfs_ms, plan_ms, build_ms, expanded, found = [], [], [], [], [], 0
    for k in range(n):
        arena = _layout(rng)
        t, grid = _ms(OccupancyGrid.build, arena)
        build_ms.append(t)
        start = (0.9, rng.uniform(0.8, 3.1))
        goal = (6.6, rng.uniform(0.8, 3.1))
        s, g = grid.cell_of(*start), grid.cell_of(*goal)
        assert s is not None and g is not None
        # Alternate the order so neither search always runs on a warm cache.
        if k % 2:
            t_bfs, _ = _ms(bfs_steps, grid.blocked, s, g)
            t_astar, res = _ms(astar, grid.blocked, grid.cost, s, g)
        else:
            t_astar, res = _ms(astar, grid.blocked, grid.cost, s, g)
            t_bfs, _ = _ms(bfs_steps, grid.blocked, s, g)
        astar_ms.append(t_astar)
        bfs_ms.append(t_bfs)
        expanded.append(res.expanded)
        planner = Planner(arena)
        t_plan, plan = _ms(planner.plan, Pose(start[0], start[1], 0.0), goal, 0.0)
        plan_ms.append(t_plan)
        found += plan.ok
    progress(f"planner: {n} queries, A* p50 {summary(astar_ms)['p50']} ms")
    empty = OccupancyGrid.build(ArenaMap())
    corner_a, corner_b = empty.cell_of(0.5, 0.5), empty.cell_of(6.85, 3.35)
    assert corner_a is not None and corner_b is not None
    t_empty, res_empty = _ms(astar, empty.blocked, empty.cost, corner_a, corner_b)
    t_empty_bfs, _ = _ms(bfs_steps, empty.blocked, corner_a, corner_b)
    sa, sb, sp = summary(astar_ms), summary(bfs_ms), summary(plan_ms)
    return {
        "grid": {"cells": list(empty.shape), "resolution_m": empty.resolution,
                 "inflation_m": empty.config.inflation_m},
        "queries": n,
        "plans_found": found,
        "astar_ms": {k: compare(sa[k], sb[k]) for k in ("p50", "p99", "max", "mean")},
        "astar_expanded": summary(expanded, 0),
        "plan_ms": {k: compare(sp[k], sa[k]) for k in ("p50", "p99", "max", "mean")},
        "grid_build_ms": summary(build_ms, 2),
        "empty_arena_corner_to_corner_ms": compare(round(t_empty, 1), round(t_empty_bfs, 1)),
        "empty_arena_expanded": res_empty.expanded,
        "note": "astar_ms baseline: BFS on the same grid and cells; plan_ms baseline: A* "
                "alone (the rest is shortcutting, footprint checks and manoeuvres)",
    }
