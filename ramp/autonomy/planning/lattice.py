"""The fallback for tight layouts: A* over position and heading, with the exact footprint.

The grid planner moves a disc of the robot's half-width and checks the rectangle afterwards;
in a layout whose only way through is a gap barely wider than the robot, at an angle, every
path it finds needs a turn where the rectangle does not fit. Here the state is a cell and one
of 48 headings, so the search itself knows where the rectangle fits at which heading:

- headings are the directions of the 48 moves (1,0), (5,1), (4,1), (3,1), (2,1), (3,2),
  (1,1), ... (no two more than 12 degrees apart), so a straight move goes exactly along its
  heading. The shallow ones (11 and 14 deg off an axis) are how a robot reaches a passage
  along a wall it cannot turn in: down at a slant it can still turn square out of there;
- primitives: a straight move forwards or backwards (reversing lets it back out of a pocket
  and line up, as a driver would), and a turn in place to the next heading either way;
- validity, precomputed with numpy for every cell: the footprint at each heading, and swept
  through each turn between neighbouring headings, keeps the check margin.

The result goes through the same exact check as every plan. It costs more (about 20 ms of
numpy per heading to precompute, then a Python search over up to 32 x the cells), so the
planner calls it only when the grid planner has failed.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ramp.autonomy.planning.geometry import (
    ArenaMap,
    Pose,
    footprint_clearance,
    point_clearance,
    rotation_poses,
    segment_poses,
    wrap_angle,
)
from ramp.autonomy.planning.grid import OccupancyGrid, PlannerConfig

# The first octant's moves (0, 11.3, 14.0, 18.4, 26.6, 33.7, 45 deg), mirrored into all eight.
_OCTANT = ((1, 0), (5, 1), (4, 1), (3, 1), (2, 1), (3, 2), (1, 1))
MOVES = tuple(sorted({m for a, b in _OCTANT for m in (
    (a, b), (b, a), (-b, a), (-a, b), (-a, -b), (-b, -a), (b, -a), (a, -b))},
    key=lambda m: math.atan2(m[1], m[0]) % (2 * math.pi)))
THETA = tuple(math.atan2(dj, di) for di, dj in MOVES)
H = len(MOVES)
REVERSE_FACTOR = 1.5  # a metre driven backwards costs this many forwards
TURN_COST_PER_RAD = 0.5  # metres of driving one radian of turning in place is worth
MAX_EXPANSIONS = 250_000
# The lattice tests the footprint at cell centres and the ends of straight moves; between
# them the exact check (every 2.5 cm) may find a few millimetres less. A plan from here is
# accepted that much below the check margin.
LATTICE_TOLERANCE_M = 0.005


@dataclass(frozen=True)
class LatticeStep:
    cell: tuple[int, int]
    heading: int
    move: str  # "start", "fwd", "rev", "turn"


class HeadingLattice:
    """Where the footprint fits, per cell and heading, and the search over it."""

    def __init__(self, arena: ArenaMap, config: PlannerConfig, grid: OccupancyGrid) -> None:
        self.arena, self.config, self.grid = arena, config, grid
        robot = config.robot
        self._hl, self._hw = robot.half_length_m, robot.half_width_m
        margin = config.check_margin_m
        gx, gy = grid.cell_centres()
        shape = grid.shape
        flat_x, flat_y = gx.ravel(), gy.ravel()
        centre_clear = point_clearance(arena, flat_x, flat_y)
        # Far enough from everything to spin freely: no need to test any heading there.
        spin_free = centre_clear >= robot.circumradius_m + margin
        near = np.nonzero(~spin_free & (centre_clear >= robot.half_width_m))[0]
        self.pose_ok = np.zeros((H, *shape), dtype=bool)
        self.turn_ok = np.zeros((H, *shape), dtype=bool)  # turn h -> h+1 (and back)
        for h in range(H):
            ok = spin_free.copy()
            ok[near] = self._clear_at(flat_x[near], flat_y[near], [THETA[h]]) >= margin
            self.pose_ok[h] = ok.reshape(shape)
        for h in range(H):
            a, b = THETA[h], THETA[h] + wrap_angle(THETA[(h + 1) % H] - THETA[h])
            yaws = np.linspace(a, b, max(2, math.ceil(abs(b - a) / math.radians(3.0)) + 1))
            ok = spin_free.copy()
            ok[near] = self._clear_at(flat_x[near], flat_y[near], list(yaws)) >= margin
            self.turn_ok[h] = ok.reshape(shape) & self.pose_ok[h] & \
                self.pose_ok[(h + 1) % H]

    def _clear_at(self, xs: NDArray[np.float64], ys: NDArray[np.float64],
                  yaws: list[float]) -> NDArray[np.float64]:
        """Least footprint clearance at each point over the given yaws."""
        out = np.full(len(xs), np.inf)
        for yaw in yaws:
            poses = np.column_stack([xs, ys, np.full(len(xs), yaw)])
            out = np.minimum(out, footprint_clearance(self.arena, poses, self._hl, self._hw))
        return out

    def _exact_turn_ok(self, xy: tuple[float, float], yaw0: float, yaw1: float,
                       margin: float) -> bool:
        poses = rotation_poses(xy, yaw0, yaw1, math.radians(3.0))
        return bool(footprint_clearance(self.arena, poses, self._hl, self._hw).min() >= margin)

    def search(self, start: Pose, goal: tuple[float, float], goal_yaw: float | None,
               start_margin: float) -> list[LatticeStep] | None:
        """Cheapest sequence of moves and turns from the start pose to the goal (and able to
        turn to `goal_yaw` there), or None."""
        grid = self.grid
        nx, ny = grid.shape
        s_cell, g_cell = grid.cell_of(start.x, start.y), grid.cell_of(*goal)
        if s_cell is None or g_cell is None:
            return None
        res = grid.resolution
        cost = grid.cost.ravel().tolist()
        pose_ok = self.pose_ok.reshape(H, -1).tolist()
        turn_ok = self.turn_ok.reshape(H, -1).tolist()
        gi, gj = g_cell
        goal_ok: dict[int, bool] = {}

        def at_goal(h: int) -> bool:
            if goal_yaw is None:
                return True
            if h not in goal_ok:
                goal_ok[h] = self._exact_turn_ok(goal, THETA[h], goal_yaw,
                                                 self.config.check_margin_m)
            return goal_ok[h]

        def heuristic(i: int, j: int) -> float:
            dx, dy = abs(i - gi), abs(j - gj)
            return (dx + dy + (math.sqrt(2.0) - 2.0) * min(dx, dy)) * res

        s_idx = s_cell[0] * ny + s_cell[1]
        best: dict[tuple[int, int], float] = {}
        parent: dict[tuple[int, int], tuple[tuple[int, int] | None, str]] = {}
        heap: list[tuple[float, float, int, int]] = []
        for h in range(H):
            if self._exact_turn_ok(start.xy, start.yaw, THETA[h], start_margin):
                g = TURN_COST_PER_RAD * abs(wrap_angle(THETA[h] - start.yaw))
                best[(s_idx, h)] = g
                parent[(s_idx, h)] = (None, "start")
                heapq.heappush(heap, (g + heuristic(*s_cell), g, s_idx, h))
        expansions = 0
        closed: set[tuple[int, int]] = set()
        while heap and expansions < MAX_EXPANSIONS:
            _f, g, idx, h = heapq.heappop(heap)
            state = (idx, h)
            if state in closed:
                continue
            closed.add(state)
            expansions += 1
            i, j = divmod(idx, ny)
            if (i, j) == g_cell and at_goal(h):
                return self._unwind(parent, state, ny)
            di, dj = MOVES[h]
            step = math.hypot(di, dj) * res
            for sign, name, factor in ((1, "fwd", 1.0), (-1, "rev", REVERSE_FACTOR)):
                a, b = i + sign * di, j + sign * dj
                if not (0 <= a < nx and 0 <= b < ny):
                    continue
                n = a * ny + b
                if not pose_ok[h][n]:
                    continue
                new = g + step * factor * 0.5 * (cost[idx] + cost[n])
                if new < best.get((n, h), math.inf):
                    best[(n, h)] = new
                    parent[(n, h)] = (state, name)
                    heapq.heappush(heap, (new + heuristic(a, b), new, n, h))
            left, right = (h + 1) % H, (h - 1) % H
            for nh, ok in ((left, turn_ok[h][idx]), (right, turn_ok[right][idx])):
                if not ok:
                    continue
                new = g + TURN_COST_PER_RAD * abs(wrap_angle(THETA[nh] - THETA[h]))
                if new < best.get((idx, nh), math.inf):
                    best[(idx, nh)] = new
                    parent[(idx, nh)] = (state, "turn")
                    heapq.heappush(heap, (new + heuristic(i, j), new, idx, nh))
        return None

    @staticmethod
    def _unwind(parent: dict[tuple[int, int], tuple[tuple[int, int] | None, str]],
                state: tuple[int, int], ny: int) -> list[LatticeStep]:
        steps = []
        cur: tuple[int, int] | None = state
        while cur is not None:
            prev, move = parent[cur]
            steps.append(LatticeStep(divmod(cur[0], ny), cur[1], move))
            cur = prev
        steps.reverse()
        return steps


def steps_to_polylines(steps: list[LatticeStep], grid: OccupancyGrid, start: Pose,
                       goal: tuple[float, float]) -> list[tuple[list[tuple[float, float]], bool]]:
    """Split the moves into legs of one direction: [(points, reverse)], exact ends."""
    legs: list[tuple[list[tuple[float, float]], bool]] = []
    points: list[tuple[float, float]] = [start.xy]
    direction = ""
    for step in steps[1:]:
        if step.move == "turn":
            continue
        if direction and step.move != direction:
            legs.append((points, direction == "rev"))
            points = [points[-1]]
        direction = step.move
        points.append(grid.centre_of(step.cell))
    if direction:
        points[-1] = goal
        legs.append((points, direction == "rev"))
    return legs


def sweep_is_clear(arena: ArenaMap, config: PlannerConfig, p: tuple[float, float],
                   q: tuple[float, float], yaw: float, reverse: bool, margin: float) -> bool:
    """Turn at p from `yaw` to face along p->q (or away from it, reversing), then slide."""
    d = math.atan2(q[1] - p[1], q[0] - p[0])
    seg_yaw = wrap_angle(d + math.pi) if reverse else d
    poses = np.vstack([rotation_poses(p, yaw, seg_yaw, math.radians(3.0)),
                       segment_poses(p, q, seg_yaw, 0.025)])
    robot = config.robot
    clear = footprint_clearance(arena, poses, robot.half_length_m, robot.half_width_m)
    return bool(clear.min() >= margin)
