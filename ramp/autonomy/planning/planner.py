"""Plan a drive from a pose to a goal: A* on the inflated grid, shortcut, check, repair.

1. **Get clear.** A robot that starts against a wall (a start box, the collector) may have no
   room to turn. If the direct plan would sweep its footprint into something, a small search
   over short straight moves and 11.25-degree turns in place (exact footprint checks, never
   closer than it already is) finds the nearest pose where it can spin freely.
2. **A*** from there to the goal on the grid (8-connected, octile heuristic, costs that keep
   turning room where the arena allows).
3. **Shortcut** the cell path with line-of-sight on the inflated grid, keeping a shortcut only
   if it is no costlier than the cells it replaces and the footprint's exact sweep (turn at
   the vertex, then slide) stays clear; then densify into waypoints.
4. **Check** the whole drive exactly (`path.swept_poses`); if a turn somewhere would bring the
   footprint within half the margin of something, keep A* away from that spot and plan again
   (a few times), else answer why not.

Pure numpy and Python, deterministic, no I/O: the state machine calls it and gets either legs
to drive or a sentence saying why there is no way.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ramp.autonomy.planning.astar import astar
from ramp.autonomy.planning.geometry import (
    ArenaMap,
    FloatArray,
    Pose,
    footprint_clearance,
    point_clearance,
    rotation_poses,
    segment_poses,
    wrap_angle,
)
from ramp.autonomy.planning.grid import OccupancyGrid, PlannerConfig
from ramp.autonomy.planning.lattice import (
    LATTICE_TOLERANCE_M,
    HeadingLattice,
    steps_to_polylines,
    sweep_is_clear,
)
from ramp.autonomy.planning.path import Path, densify, end_yaw, swept_poses

Point = tuple[float, float]

ESCAPE_HEADINGS = 32  # turns in place of 11.25 degrees
ESCAPE_STEP_M = 0.05
ESCAPE_RADIUS_M = 2.0  # how far from the start the search may go
ESCAPE_MAX_EXPANSIONS = 6000
MAX_REPAIRS = 4
NEAR_GOAL_M = 0.15  # a start this near a goal without room to spin goes straight to it
STEP_MIN_M = 0.02  # nearer than this: only the turn
SHORTCUT_TRIES = 8  # exact sweep checks per vertex when shortcutting
REPAIR_RADIUS_M = 0.5  # a failed turn makes A* pay to pass within this of it ...
REPAIR_COST = 6.0  # ... up to this much extra per cell at the spot itself
POORLY_SEEN_COST = 2.0  # extra per cell with the robot's centre at poorly seen ground


@dataclass(frozen=True)
class PlanResult:
    """Legs to drive in order (each a `Path`), or an empty tuple and a `reason`."""

    legs: tuple[Path, ...]
    reason: str = ""
    expanded: int = 0  # A* cells expanded, over every attempt
    min_clearance_m: float = math.nan  # of the footprint along the whole drive
    margin_m: float = math.nan  # the margin the plan was made with

    @property
    def ok(self) -> bool:
        return bool(self.legs) and not self.reason

    @property
    def length_m(self) -> float:
        return sum(leg.length for leg in self.legs)


class Planner:
    """Paths for MARTE's footprint through a known arena (walls and round obstacles).

    Plans keep `config.margin_m` between the footprint and anything where the layout allows;
    when no plan does, it tries again with `config.min_margin_m` (the result says which).
    `poorly_seen` (k, 2), centres of ground the scans saw too thinly to trust
    (`perception.coverage`): A* pays up to `POORLY_SEEN_COST` more per cell to bring the
    robot's centre within its circumradius of one, so plans keep the footprint, at any yaw,
    off such ground where they can; nothing is closed by it.
    """

    def __init__(self, arena: ArenaMap, config: PlannerConfig | None = None, *,
                 poorly_seen: FloatArray | None = None) -> None:
        self.arena = arena
        self.config = config or PlannerConfig()
        self.poorly_seen = np.zeros((0, 2)) if poorly_seen is None else poorly_seen
        self._levels = [_MarginPlanner(arena, self.config, self.poorly_seen)]
        if self.config.min_margin_m < self.config.margin_m:
            self._levels.append(_MarginPlanner(
                arena, replace(self.config, margin_m=self.config.min_margin_m),
                self.poorly_seen))

    @property
    def grid(self) -> OccupancyGrid:
        """The grid at the nominal margin."""
        return self._levels[0].grid

    @property
    def loosest_grid(self) -> OccupancyGrid:
        """The grid at the smallest margin the planner will accept: what is reachable at all."""
        return self._levels[-1].grid

    def clearance(self, poses: FloatArray, *, x0_wall: bool = True) -> FloatArray:
        return self._levels[0].clearance(poses, x0_wall=x0_wall)

    def legs_clearance(self, legs: Sequence[Path], start_yaw: float, *,
                       x0_wall: bool = True) -> tuple[float, FloatArray]:
        return self._levels[0].legs_clearance(legs, start_yaw, x0_wall=x0_wall)

    def can_spin_at(self, x: float, y: float) -> bool:
        return self._levels[0].can_spin_at(x, y)

    def accepts(self, legs: Sequence[Path], start_yaw: float) -> bool:
        """True when driving `legs` from a pose of `start_yaw` keeps the footprint as far
        from everything as the planner's loosest plan may (the check a plan it makes
        passes): a plan made from a pose a few centimetres away, driven on from here."""
        level = self._levels[-1]
        clear, _pose = level.legs_clearance(legs, start_yaw)
        return clear >= level.config.check_margin_m - LATTICE_TOLERANCE_M

    def plan(self, start: Pose, goal: Point, goal_yaw: float | None = None, *,
             headings: bool = True) -> PlanResult:
        """Legs from `start` to `goal` (then turned to `goal_yaw` if given), or why not.

        The grid at the nominal margin, then at the smallest; then, unless `headings` is
        False, the search over headings (`plan_over_headings`), which costs up to seconds
        where it finds nothing: a caller with several goals to try tries them all on the
        grid first."""
        first = self._levels[0].plan(start, goal, goal_yaw)
        if first.ok or len(self._levels) == 1:
            return first
        second = self._levels[1].plan(start, goal, goal_yaw)
        expanded = first.expanded + second.expanded
        if second.ok:
            return replace(second, expanded=expanded)
        if second.reason.startswith(("goal:", "start")) or not headings:
            return replace(second, expanded=expanded)
        # Last resort: search over headings too, where the footprint fits at each.
        third = self.plan_over_headings(start, goal, goal_yaw)
        if third.ok:
            return replace(third, expanded=expanded + third.expanded)
        return replace(second, reason=f"{second.reason}; searching over headings too: "
                                      f"{third.reason}", expanded=expanded + third.expanded)

    def plan_over_headings(self, start: Pose, goal: Point,
                           goal_yaw: float | None = None) -> PlanResult:
        """The search over position and heading alone (`lattice.py`), at the smallest
        margin: for a gap barely wider than the robot, where the grid's turns never fit."""
        return self._levels[-1].plan_lattice(start, goal, goal_yaw)


class _MarginPlanner:
    """The planner at one margin."""

    def __init__(self, arena: ArenaMap, config: PlannerConfig,
                 poorly_seen: FloatArray) -> None:
        self.arena = arena
        self.config = config
        self.grid = OccupancyGrid.build(arena, config).with_poorly_seen(
            poorly_seen, config.robot.circumradius_m, POORLY_SEEN_COST)
        robot = config.robot
        self._hl, self._hw = robot.half_length_m, robot.half_width_m
        self._lattice: HeadingLattice | None = None

    # -- checks --------------------------------------------------------------------------------
    def clearance(self, poses: FloatArray, *, x0_wall: bool = True) -> FloatArray:
        """Exact clearance of the footprint at each pose (negative: overlap)."""
        return footprint_clearance(self.arena, poses, self._hl, self._hw, x0_wall=x0_wall)

    def legs_clearance(self, legs: Sequence[Path], start_yaw: float, *,
                       x0_wall: bool = True) -> tuple[float, FloatArray]:
        """Least clearance of the footprint over every pose of the legs, and that pose."""
        yaw = start_yaw
        chunks = []
        for leg in legs:
            chunks.append(swept_poses(leg, yaw))
            yaw = end_yaw(leg, yaw)
        poses = np.vstack(chunks)
        clear = self.clearance(poses, x0_wall=x0_wall)
        k = int(np.argmin(clear))
        return float(clear[k]), poses[k]

    def can_spin_at(self, x: float, y: float) -> bool:
        """True when the footprint could turn full circle here with the check margin kept."""
        c = point_clearance(self.arena, np.array([x]), np.array([y]))[0]
        return bool(c >= self.config.robot.circumradius_m + self.config.check_margin_m)

    # -- planning ------------------------------------------------------------------------------
    def plan(self, start: Pose, goal: Point, goal_yaw: float | None = None) -> PlanResult:
        why = self._check_ends(start, goal, goal_yaw)
        if why:
            return PlanResult((), why)
        # A goal pose with no room to spin is entered by the reverse of a way out of it.
        tail: list[Path] = []
        target, target_yaw = goal, goal_yaw
        if goal_yaw is not None and not self.can_spin_at(*goal):
            near = self._short_step(start, goal, goal_yaw)
            if near is not None:
                return near
            way_out = self._escape(Pose(goal[0], goal[1], goal_yaw))
            if way_out is None:
                return PlanResult((), f"goal: no room to turn into the pose ({goal[0]:.2f}, "
                                      f"{goal[1]:.2f}, {math.degrees(goal_yaw):.0f} deg) near "
                                      f"{self.arena.describe_nearest(*goal)}")
            legs_out, clear_pose = way_out
            if legs_out:
                tail = _reversed(legs_out, goal_yaw)
                target = clear_pose.xy
                first = tail[0]
                target_yaw = first.motion_yaw(_first_direction(first))
        result = self._plan_head(start, target, target_yaw)
        if not result.ok or not tail:
            return result
        legs = _merge(list(result.legs) + tail)
        clear, _pose = self.legs_clearance(legs, start.yaw)
        return PlanResult(tuple(legs), "", result.expanded, clear, self.config.margin_m)

    def _short_step(self, start: Pose, goal: Point, goal_yaw: float) -> PlanResult | None:
        """Almost there (a fix a few centimetres off a goal with no room to spin): straight
        to the goal, forwards or backwards as it lies, then the turn to `goal_yaw`, when that
        fits; else None. Without it, a re-plan from beside such a goal leaves it to come in
        again by the way in, arrives beside it again, and never ends."""
        dx, dy = goal[0] - start.x, goal[1] - start.y
        dist = math.hypot(dx, dy)
        if dist > NEAR_GOAL_M:
            return None
        if dist < STEP_MIN_M:
            leg = Path(np.array([start.xy]), final_yaw=goal_yaw)
        else:
            ahead = abs(wrap_angle(math.atan2(dy, dx) - start.yaw)) <= math.pi / 2
            leg = Path(np.array([start.xy, goal]), reverse=not ahead, final_yaw=goal_yaw)
        clear, _pose = self.legs_clearance([leg], start.yaw)
        if clear < min(self.config.check_margin_m, self._start_clearance(start)) - 1e-6:
            return None
        return PlanResult((leg,), "", 0, clear, self.config.margin_m)

    def _plan_head(self, start: Pose, goal: Point, goal_yaw: float | None) -> PlanResult:
        """Plan from the start, getting clear of where it stands first if it must."""
        direct = PlanResult((), "the start is too close to "
                                f"{self.arena.describe_nearest(start.x, start.y)} to plan from")
        if self.grid.is_free(start.x, start.y):
            direct = self._plan_from(start, goal, goal_yaw)
            if direct.ok or direct.reason.startswith("goal:"):
                return direct
        escape = self._escape(start)
        if escape is None:
            return PlanResult((), f"no room to manoeuvre: from ({start.x:.2f}, {start.y:.2f}) "
                                  "no short move gets the robot clear of "
                                  f"{self.arena.describe_nearest(start.x, start.y)}",
                              direct.expanded)
        legs, clear_pose = escape
        if not legs:
            return direct
        main = self._plan_from(clear_pose, goal, goal_yaw)
        expanded = direct.expanded + main.expanded
        if not main.ok:
            return PlanResult((), main.reason, expanded)
        all_legs = _merge(legs + list(main.legs))
        clear, _pose = self.legs_clearance(all_legs, start.yaw)
        return PlanResult(tuple(all_legs), "", expanded, clear, self.config.margin_m)

    def _check_ends(self, start: Pose, goal: Point, goal_yaw: float | None) -> str:
        a = self.arena
        if not (0 < start.x < a.length and 0 < start.y < a.width):
            return f"start ({start.x:.2f}, {start.y:.2f}) is outside the arena"
        if self._start_clearance(start) < 0:
            return (f"start pose ({start.x:.2f}, {start.y:.2f}, "
                    f"{math.degrees(start.yaw):.0f} deg) overlaps "
                    f"{a.describe_nearest(start.x, start.y)}")
        gx, gy = goal
        if not (0 < gx < a.length and 0 < gy < a.width):
            return f"goal: ({gx:.2f}, {gy:.2f}) is outside the arena"
        if not self.grid.is_free(gx, gy):
            return (f"goal: ({gx:.2f}, {gy:.2f}) is too close to "
                    f"{a.describe_nearest(gx, gy)}; the robot's centre must keep "
                    f"{self.config.inflation_m:.2f} m from walls and obstacle edges")
        if goal_yaw is not None and \
                self.clearance(np.array([[gx, gy, goal_yaw]]))[0] < self.config.check_margin_m:
            return (f"goal: the pose ({gx:.2f}, {gy:.2f}, {math.degrees(goal_yaw):.0f} deg) "
                    f"puts the footprint within {self.config.check_margin_m:.2f} m of "
                    f"{a.describe_nearest(gx, gy)}")
        return ""

    def _start_clearance(self, start: Pose) -> float:
        return float(self.clearance(np.array([[start.x, start.y, start.yaw]]))[0])

    def _plan_from(self, start: Pose, goal: Point, goal_yaw: float | None) -> PlanResult:
        """A*, shortcut, check; where a turn fails the check, make A* pay for passing there
        and plan again."""
        cfg = self.config
        grid = self.grid
        trouble: list[Point] = []
        expanded = 0
        s_cell, g_cell = grid.cell_of(start.x, start.y), grid.cell_of(*goal)
        assert s_cell is not None and g_cell is not None
        for _attempt in range(MAX_REPAIRS + 1):
            result = astar(grid.blocked, grid.cost, s_cell, g_cell)
            expanded += result.expanded
            if result.cells is None:
                return PlanResult((), "no way through: the walls and obstacles, kept "
                                      f"{cfg.inflation_m:.2f} m from the robot's centre, leave "
                                      f"no passage from ({start.x:.2f}, {start.y:.2f}) to "
                                      f"({goal[0]:.2f}, {goal[1]:.2f})", expanded)
            raw = [start.xy] + [grid.centre_of(c) for c in result.cells[1:-1]] + [goal]
            vertices = self._shortcut(grid, raw, start.yaw)
            path = Path(densify(vertices, cfg.waypoint_spacing_m), final_yaw=goal_yaw)
            clear, pose = self.legs_clearance([path], start.yaw)
            if clear >= cfg.check_margin_m:
                return PlanResult((path,), "", expanded, clear, cfg.margin_m)
            px, py = float(pose[0]), float(pose[1])
            if math.hypot(px - start.x, py - start.y) < 1e-6:
                return PlanResult((), "the first turn at the start would come within "
                                      f"{cfg.check_margin_m:.3f} m of "
                                      f"{self.arena.describe_nearest(px, py)}", expanded)
            if math.hypot(px - goal[0], py - goal[1]) < 1e-6:
                return PlanResult((), "goal: the footprint cannot turn to its final heading "
                                      "there without coming near "
                                      f"{self.arena.describe_nearest(px, py)}", expanded)
            trouble.append((px, py))
            grid = self.grid.with_penalty(trouble, REPAIR_RADIUS_M, REPAIR_COST)
        return PlanResult((), f"no way found without a turn too close to "
                              f"{self.arena.describe_nearest(*trouble[-1])} (tried "
                              f"{len(trouble)} detours)", expanded)

    def _shortcut(self, grid: OccupancyGrid, raw: list[Point], start_yaw: float) -> list[Point]:
        """Greedy line-of-sight shortcutting that keeps A*'s clearance and the exact sweep."""
        n = len(raw)
        if n <= 2:
            return raw
        step_cost = [grid.line_cost(raw[k], raw[k + 1]) for k in range(n - 1)]
        cum = np.concatenate([[0.0], np.cumsum(step_cost)])
        out = [raw[0]]
        i, yaw = 0, start_yaw
        while i < n - 1:
            candidates = [i + 1]
            for j in range(i + 2, n):
                if not grid.line_is_free(raw[i], raw[j]):
                    break
                if grid.line_cost(raw[i], raw[j]) <= cum[j] - cum[i] + 1e-6:
                    candidates.append(j)
            chosen = candidates[0]
            if len(candidates) > SHORTCUT_TRIES:  # farthest first, then evenly nearer
                picks = np.linspace(len(candidates) - 1, 0, SHORTCUT_TRIES).round().astype(int)
                candidates = [candidates[k] for k in sorted(set(picks.tolist()))]
            for j in reversed(candidates):
                if self._move_is_clear(raw[i], raw[j], yaw):
                    chosen = j
                    break
            p, q = raw[i], raw[chosen]
            yaw = math.atan2(q[1] - p[1], q[0] - p[0])
            out.append(q)
            i = chosen
        return out

    def _move_is_clear(self, p: Point, q: Point, yaw: float) -> bool:
        seg_yaw = math.atan2(q[1] - p[1], q[0] - p[0])
        poses = np.vstack([rotation_poses(p, yaw, seg_yaw, math.radians(3.0)),
                           segment_poses(p, q, seg_yaw, 0.025)])
        return bool(self.clearance(poses).min() >= self.config.check_margin_m)

    # -- the fallback over headings ----------------------------------------------------------
    def plan_lattice(self, start: Pose, goal: Point, goal_yaw: float | None) -> PlanResult:
        """Plan with the position-and-heading search (`lattice.py`), after getting clear of
        the start if it has no room to turn."""
        head: list[Path] = []
        if not self.can_spin_at(start.x, start.y):
            escape = self._escape(start)
            if escape is not None and escape[0]:
                head, clear_pose = escape
                result = self._lattice_from(clear_pose, goal, goal_yaw)
                if not result.ok:
                    return result
                legs = _merge(head + list(result.legs))
                clear, _pose = self.legs_clearance(legs, start.yaw)
                return PlanResult(tuple(legs), "", result.expanded, clear, self.config.margin_m)
        return self._lattice_from(start, goal, goal_yaw)

    def _lattice_from(self, start: Pose, goal: Point, goal_yaw: float | None) -> PlanResult:
        cfg = self.config
        if self._lattice is None:
            self._lattice = HeadingLattice(self.arena, cfg, self.grid)
        margin_start = min(cfg.check_margin_m, self._start_clearance(start)) - 1e-6
        steps = self._lattice.search(start, goal, goal_yaw, margin_start)
        if steps is None:
            return PlanResult((), "no sequence of straight moves and turns in place fits the "
                                  "footprint through")
        legs: list[Path] = []
        yaw = start.yaw
        for points, reverse in steps_to_polylines(steps, self.grid, start, goal):
            margin = margin_start if not legs else cfg.check_margin_m - LATTICE_TOLERANCE_M
            vertices = self._shortcut_exact(points, yaw, reverse, margin)
            leg = Path(densify(vertices, cfg.waypoint_spacing_m), reverse=reverse)
            if self.legs_clearance([leg], yaw)[0] < margin:
                # A shortcut changed the heading the robot reaches a later vertex with, and
                # the turn there no longer fits: keep the search's own moves.
                leg = Path(densify(points, cfg.waypoint_spacing_m), reverse=reverse)
            legs.append(leg)
            yaw = end_yaw(leg, yaw)
        if not legs:  # already in the goal cell: at most a turn
            legs.append(Path(np.array([start.xy, goal])))
        last = legs[-1]
        legs[-1] = Path(last.points, reverse=last.reverse, final_yaw=goal_yaw)
        clear, pose = self.legs_clearance(legs, start.yaw)
        if clear < min(margin_start, cfg.check_margin_m - LATTICE_TOLERANCE_M):
            return PlanResult((), "the search over headings found a way the exact check "
                                  f"rejects near ({pose[0]:.2f}, {pose[1]:.2f})")
        return PlanResult(tuple(_merge(legs)), "", 0, clear, cfg.margin_m)

    def _shortcut_exact(self, points: list[Point], yaw: float, reverse: bool,
                        first_margin: float) -> list[Point]:
        """Greedy shortcuts checked by the exact sweep alone (no grid: the disc model is what
        failed here)."""
        out = [points[0]]
        i, n = 0, len(points)
        while i < n - 1:
            margin = first_margin if i == 0 else self.config.check_margin_m
            picks = np.unique(np.linspace(n - 1, i + 1, min(n - 1 - i, 16)).round()
                              .astype(int)).tolist()
            chosen = i + 1
            for j in sorted(picks, reverse=True):
                if sweep_is_clear(self.arena, self.config, points[i], points[j], yaw, reverse,
                                  margin):
                    chosen = j
                    break
            p, q = points[i], points[chosen]
            d = math.atan2(q[1] - p[1], q[0] - p[0])
            yaw = wrap_angle(d + math.pi) if reverse else d
            out.append(q)
            i = chosen
        return out

    # -- getting clear ---------------------------------------------------------------------------
    def _escape(self, start: Pose) -> tuple[list[Path], Pose] | None:
        """Short straight moves and turns in place from `start` to the nearest pose where the
        robot can spin freely (best-first on the clearance it still lacks)."""
        cfg = self.config
        need = cfg.robot.circumradius_m + cfg.check_margin_m
        margin = min(cfg.check_margin_m, self._start_clearance(start)) - 1e-6
        dtheta = 2.0 * math.pi / ESCAPE_HEADINGS
        # States closer than half a step share a key; a step always reaches a new one.
        res = 0.5 * ESCAPE_STEP_M

        def key(x: float, y: float, yaw: float) -> tuple[int, int, int]:
            return (round(x / res), round(y / res),
                    round(wrap_angle(yaw) / dtheta) % ESCAPE_HEADINGS)

        def lack(x: float, y: float) -> float:
            c = float(point_clearance(self.arena, np.array([x]), np.array([y]))[0])
            return max(0.0, need - c)

        # Node: (x, y, yaw); parent link holds the move that led there.
        parents: dict[tuple[int, int, int], tuple[tuple[int, int, int] | None, str,
                                                  tuple[float, float, float]]] = {}
        k0 = key(start.x, start.y, start.yaw)
        parents[k0] = (None, "", (start.x, start.y, start.yaw))
        best_g = {k0: 0.0}
        heap: list[tuple[float, float, tuple[int, int, int]]] = [
            (lack(start.x, start.y), 0.0, k0)]
        expansions = 0
        while heap and expansions < ESCAPE_MAX_EXPANSIONS:
            _f, g, k = heapq.heappop(heap)
            if g > best_g[k]:
                continue
            x, y, yaw = parents[k][2]
            if lack(x, y) == 0.0 and self.grid.is_free(x, y):
                return self._escape_legs(parents, k)
            expansions += 1
            snapped = round(yaw / dtheta) * dtheta
            moves: list[tuple[str, tuple[float, float, float], FloatArray, float]] = []
            for sign, name in ((1.0, "fwd"), (-1.0, "rev")):
                nx_ = x + sign * ESCAPE_STEP_M * math.cos(yaw)
                ny_ = y + sign * ESCAPE_STEP_M * math.sin(yaw)
                moves.append((name, (nx_, ny_, yaw),
                              segment_poses((x, y), (nx_, ny_), yaw, 0.025),
                              ESCAPE_STEP_M * (1.0 if sign > 0 else 1.2)))
            for turn in (1, -1):
                new_yaw = wrap_angle(snapped + turn * dtheta)
                moves.append(("turn", (x, y, new_yaw),
                              rotation_poses((x, y), yaw, new_yaw, math.radians(3.0)),
                              0.3 * abs(wrap_angle(new_yaw - yaw))))
            for name, (mx, my, myaw), poses, cost in moves:
                if math.hypot(mx - start.x, my - start.y) > ESCAPE_RADIUS_M:
                    continue
                nk = key(mx, my, myaw)
                ng = g + cost
                if ng >= best_g.get(nk, math.inf):
                    continue
                if self.clearance(poses).min() < margin:
                    continue
                best_g[nk] = ng
                parents[nk] = (k, name, (mx, my, myaw))
                heapq.heappush(heap, (ng + 2.0 * lack(mx, my), ng, nk))
        return None

    def _escape_legs(self, parents: dict[tuple[int, int, int], tuple[
            tuple[int, int, int] | None, str, tuple[float, float, float]]],
                     k: tuple[int, int, int]) -> tuple[list[Path], Pose]:
        chain: list[tuple[str, tuple[float, float, float]]] = []
        cur: tuple[int, int, int] | None = k
        while cur is not None:
            parent, move, pose = parents[cur]
            chain.append((move, pose))
            cur = parent
        chain.reverse()
        end = chain[-1][1]
        legs: list[Path] = []
        points: list[Point] = [(chain[0][1][0], chain[0][1][1])]
        direction = ""
        for move, (x, y, _yaw) in chain[1:]:
            if move == "turn":
                continue
            if direction and move != direction:
                legs.append(Path(np.array(points), reverse=direction == "rev"))
                points = [points[-1]]
            direction = move
            points.append((x, y))
        if direction:
            legs.append(Path(np.array(points), reverse=direction == "rev"))
        # The turns the search made after its last straight move are left to the next leg's
        # first turn, which the planner checks on its own.
        return legs, Pose(end[0], end[1], end[2] if not legs else end_yaw(legs[-1], end[2]))


def _merge(legs: list[Path]) -> list[Path]:
    """Join consecutive legs driven the same way into one (the junction becomes a corner)."""
    out: list[Path] = []
    for leg in legs:
        if out and out[-1].reverse == leg.reverse and out[-1].final_yaw is None:
            joined = np.vstack([out[-1].points, leg.points[1:]])
            out[-1] = Path(joined, reverse=leg.reverse, final_yaw=leg.final_yaw)
        else:
            out.append(leg)
    return out


def _first_direction(leg: Path) -> float:
    """Direction (rad) of a leg's first segment, from its first two distinct waypoints."""
    pts = leg.points
    for k in range(1, len(pts)):
        d = pts[k] - pts[0]
        if math.hypot(float(d[0]), float(d[1])) > 1e-9:
            return math.atan2(float(d[1]), float(d[0]))
    return 0.0


def _reversed(legs: list[Path], final_yaw: float) -> list[Path]:
    """The same motion played backwards: last leg first, each driven the other way (the
    footprint passes through the same poses), ending turned to `final_yaw`."""
    out = [Path(leg.points[::-1].copy(), reverse=not leg.reverse) for leg in reversed(legs)]
    out[-1] = Path(out[-1].points, reverse=out[-1].reverse, final_yaw=final_yaw)
    return out
