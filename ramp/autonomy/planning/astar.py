"""A* and Dijkstra on an 8-connected grid with per-cell costs.

A step between neighbouring cells costs its length in cells (1 or sqrt 2) times the mean of
the two cells' costs (each >= 1), so the octile distance is an admissible, consistent
heuristic and A* returns a cheapest path. A diagonal step may not cut a blocked corner: both
cells it passes between must be free, or the robot's centre would graze the blocked one.

Pure Python on flat lists (a heap of ints): the RMC grid has about 11,500 cells, and this
runs in tens of milliseconds without a compiled dependency.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Cell = tuple[int, int]

SQRT2 = math.sqrt(2.0)
# (di, dj, length): orthogonal moves first, then diagonals.
MOVES = ((1, 0, 1.0), (-1, 0, 1.0), (0, 1, 1.0), (0, -1, 1.0),
         (1, 1, SQRT2), (1, -1, SQRT2), (-1, 1, SQRT2), (-1, -1, SQRT2))


@dataclass(frozen=True)
class SearchResult:
    """A cheapest cell path (start and goal included) or None, its cost in cell units and
    how many cells the search expanded."""

    cells: list[Cell] | None
    cost: float
    expanded: int


def octile(a: Cell, b: Cell) -> float:
    dx, dy = abs(a[0] - b[0]), abs(a[1] - b[1])
    return dx + dy + (SQRT2 - 2.0) * min(dx, dy)


def _neighbours(nx: int, ny: int, blocked: list[bool], idx: int) -> list[tuple[int, float]]:
    """Free neighbours of a flat index with their step lengths (no corner cutting)."""
    i, j = divmod(idx, ny)
    out: list[tuple[int, float]] = []
    for di, dj, length in MOVES:
        a, b = i + di, j + dj
        if not (0 <= a < nx and 0 <= b < ny):
            continue
        n = a * ny + b
        if blocked[n]:
            continue
        if di and dj and (blocked[a * ny + j] or blocked[i * ny + b]):
            continue
        out.append((n, length))
    return out


def astar(blocked: NDArray[np.bool_], cost: NDArray[np.float64], start: Cell,
          goal: Cell) -> SearchResult:
    """Cheapest 8-connected path from start to goal over free cells (octile heuristic)."""
    nx, ny = int(blocked.shape[0]), int(blocked.shape[1])
    blk: list[bool] = blocked.ravel().tolist()
    cst: list[float] = cost.ravel().tolist()
    s, g = start[0] * ny + start[1], goal[0] * ny + goal[1]
    if blk[s] or blk[g]:
        return SearchResult(None, math.inf, 0)
    gi, gj = goal
    best: dict[int, float] = {s: 0.0}
    parent: dict[int, int] = {}
    closed: set[int] = set()
    heap: list[tuple[float, float, int]] = [(octile(start, goal), -0.0, s)]
    expanded = 0
    while heap:
        _f, neg_g, cur = heapq.heappop(heap)
        g_cost = -neg_g
        if cur in closed:
            continue
        closed.add(cur)
        expanded += 1
        if cur == g:
            return SearchResult(_unwind(parent, g, ny), g_cost, expanded)
        c_cur = cst[cur]
        for n, length in _neighbours(nx, ny, blk, cur):
            if n in closed:
                continue
            new = g_cost + length * 0.5 * (c_cur + cst[n])
            if new < best.get(n, math.inf):
                best[n] = new
                parent[n] = cur
                a, b = divmod(n, ny)
                dx, dy = abs(a - gi), abs(b - gj)
                h = dx + dy + (SQRT2 - 2.0) * (dx if dx < dy else dy)
                # Ties on f go to the deeper node (larger g): fewer expansions, same cost.
                heapq.heappush(heap, (new + h, -new, n))
    return SearchResult(None, math.inf, expanded)


def _unwind(parent: dict[int, int], goal: int, ny: int) -> list[Cell]:
    path = [goal]
    while path[-1] in parent:
        path.append(parent[path[-1]])
    path.reverse()
    return [divmod(n, ny) for n in path]


def dijkstra(blocked: NDArray[np.bool_], cost: NDArray[np.float64],
             source: Cell) -> NDArray[np.float64]:
    """Cost (cell units) of the cheapest path from `source` to every cell; inf if unreachable.

    Same step costs as `astar`, so a distance read here is what A* would return.
    """
    nx, ny = int(blocked.shape[0]), int(blocked.shape[1])
    blk: list[bool] = blocked.ravel().tolist()
    cst: list[float] = cost.ravel().tolist()
    dist = [math.inf] * (nx * ny)
    s = source[0] * ny + source[1]
    heappush = heapq.heappush
    if not blk[s]:
        dist[s] = 0.0
        heap: list[tuple[float, int]] = [(0.0, s)]
        while heap:
            d, cur = heapq.heappop(heap)
            if d > dist[cur]:
                continue
            # `_neighbours(nx, ny, blk, cur)` written out (the same cells in the same order).
            i, j = divmod(cur, ny)
            c_cur = cst[cur]
            for di, dj, length in MOVES:
                a, b = i + di, j + dj
                if not (0 <= a < nx and 0 <= b < ny):
                    continue
                n = a * ny + b
                if blk[n] or (di and dj and (blk[a * ny + j] or blk[i * ny + b])):
                    continue
                new = d + length * 0.5 * (c_cur + cst[n])
                if new < dist[n]:
                    dist[n] = new
                    heappush(heap, (new, n))
    return np.array(dist, dtype=float).reshape(nx, ny)


def bfs_steps(blocked: NDArray[np.bool_], start: Cell, goal: Cell) -> int | None:
    """Fewest 8-connected steps from start to goal (every step 1): the benchmark's baseline,
    the cheapest search that still answers "is there a way"."""
    nx, ny = int(blocked.shape[0]), int(blocked.shape[1])
    blk: list[bool] = blocked.ravel().tolist()
    s, g = start[0] * ny + start[1], goal[0] * ny + goal[1]
    if blk[s] or blk[g]:
        return None
    depth = {s: 0}
    queue = deque([s])
    while queue:
        cur = queue.popleft()
        if cur == g:
            return depth[cur]
        for n, _length in _neighbours(nx, ny, blk, cur):
            if n not in depth:
                depth[n] = depth[cur] + 1
                queue.append(n)
    return None
