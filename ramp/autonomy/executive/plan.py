"""Plan Path (to a digging spot, home to the collector) and the vantage point of the 3D scan.

Both plans come from the planner that Detect Obstacles built (`ctx.planner`: the walls and
what the sweep found, each disc grown by the detector's error; when no digging spot can be
reached around the grown discs, once, the discs as detected: the planner keeps its own
margin, and a layout whose only gap is a few centimetres wider than the robot is driven).
The way out goes to the interrupted spot if there is one (a recovery resumes it), else to
the next spot that does not repeat (`choose_spot`: `DigSites`' ranking, nearest row and
cheapest trip from the collector's approach first, where the robot has room to turn). The
way home is `plan_to_dock`: to the longest straight approach in front of the collector that
is clear, then straight back onto the wall.

Before any obstacle is known, the robot moves only inside the start region: the vantage
point's plan uses an arena that ends at x = 1.5 (`START_REGION`), so no footprint, turning or
not, reaches where a rock may lie. The region is 1.5 m deep and MARTE turns in a circle of
1.42 m, so turns there are tight: a 5 cm grid with the usual margins first, then a 2.5 cm
grid keeping 3 cm (`START_FINE`), which finds the three-point turns a start facing a wall
needs.
"""

from __future__ import annotations

import functools
import logging
import math

import numpy as np

from ramp.autonomy import arena
from ramp.autonomy.executive.kit import Kit, yaw_error
from ramp.autonomy.executive.scan import TIGHT_NOTE, build_map
from ramp.autonomy.executive.step import Step
from ramp.autonomy.planning import (
    ArenaMap,
    DigSites,
    DigSpot,
    Path,
    Planner,
    PlannerConfig,
    PlanResult,
    Pose,
    plan_to_dock,
)
from ramp.autonomy.planning.dig_spots import PlanFn
from ramp.statemachine import Status

log = logging.getLogger("ramp.autonomy.executive")

START_REGION = ArenaMap(length=arena.START_END_X_M)
START_FINE = PlannerConfig(resolution_m=0.025, margin_m=0.06, min_margin_m=0.03)
DOCK_REFERENCE = (arena.ROBOT_LENGTH_M / 2 + 1.0, arena.COLLECTOR_Y_M)  # the approach
DIG_REFERENCE = (arena.OBSTACLE_END_X_M + 1.0, arena.COLLECTOR_Y_M)  # inside the dig region
HEADING_SEARCHES = 3  # digging spots tried with the search over headings when the grid fails
DOCK_GAP_M = 0.04  # the crossing home stops this short of the wall; Dock does the rest
VANTAGE_TOLERANCE_M = 0.12  # already this near the vantage point (and facing +x): stay
VANTAGE_YAW_DEG = 4.0
#: `ctx.notes` key: the planned length (m) of the way out being driven, for the first dig's
#: estimate of the way home (`Excavate`).
OUT_M_NOTE = "out_m"


class StartPlanners:
    """The start region's two planners, built once (the fine one when first needed)."""

    def __init__(self) -> None:
        self.coarse = Planner(START_REGION)
        self._fine: Planner | None = None

    @property
    def fine(self) -> Planner:
        if self._fine is None:
            self._fine = Planner(START_REGION, START_FINE)
        return self._fine


@functools.cache
def start_planners() -> StartPlanners:
    """The start region's planners, one set for every step that plans there (built at the
    first use; the region never changes)."""
    return StartPlanners()


def vantage_goals(kit: Kit, pose: Pose) -> list[tuple[float, float]]:
    """Where to stand for the 3D scan, best first: on the collector's line, else across
    from where the robot is (the sweep's 270 deg fan covers the region's width from
    either)."""
    vx = kit.settings.vantage_x_m
    half = arena.ROBOT_WIDTH_M / 2 + 0.1
    y = min(max(pose.y, half), arena.ARENA_WIDTH_M - half)
    goals = [(vx, arena.COLLECTOR_Y_M)]
    if abs(y - arena.COLLECTOR_Y_M) > 0.05:
        goals.append((vx, y))
    return goals


def at_vantage(kit: Kit, pose: Pose) -> bool:
    return (abs(pose.x - kit.settings.vantage_x_m) <= VANTAGE_TOLERANCE_M
            and yaw_error(pose.yaw, 0.0) <= math.radians(VANTAGE_YAW_DEG))


def plan_vantage(kit: Kit, planners: StartPlanners, pose: Pose, *,
                 headings: bool = True) -> PlanResult:
    """A plan inside the start region to a vantage point facing +x, or why there is none."""
    if at_vantage(kit, pose):
        return PlanResult((Path(np.array([[pose.x, pose.y]]), final_yaw=0.0),))
    last = PlanResult((), "no vantage point tried")
    for planner in (planners.coarse, planners.fine):
        if abs(pose.x - kit.settings.vantage_x_m) <= VANTAGE_TOLERANCE_M:
            result = planner.plan(pose, pose.xy, goal_yaw=0.0,  # a turn on the spot
                                  headings=headings)
            if result.ok:
                return result
        for goal in vantage_goals(kit, pose):
            result = planner.plan(pose, goal, goal_yaw=0.0, headings=headings)
            if result.ok:
                return result
            last = result
    return PlanResult((), f"no way to a vantage point in the start region: {last.reason}")


def trim_dock(result: PlanResult, gap: float = DOCK_GAP_M) -> PlanResult:
    """The plan home with its last leg (the straight reverse onto the wall) ending `gap`
    short of the wall."""
    if not result.ok:
        return result
    last = result.legs[-1]
    pts = last.points
    if len(pts) >= 2 and last.reverse:
        start, end = pts[0], pts[-1]
        length = float(np.hypot(*(end - start)))
        if length > gap + 0.01:
            end = end + (start - end) / length * gap
            keep = np.hypot(*(pts[:-1] - start).T) < length - gap
            pts = np.vstack([pts[:-1][keep], end])
    trimmed = Path(pts, reverse=last.reverse, final_yaw=last.final_yaw)
    return PlanResult(result.legs[:-1] + (trimmed,), result.reason, result.expanded,
                      result.min_clearance_m, result.margin_m)


def plan_home(planner: Planner, pose: Pose, *, headings: bool = True,
              ) -> tuple[PlanResult, object]:
    result, dock = plan_to_dock(planner, pose, headings=headings)
    return trim_dock(result), dock


def choose_spot(planner: Planner, sites: DigSites, pose: Pose,
                tries: int = 6) -> tuple[DigSpot | None, PlanResult]:
    """The next digging spot and the plan there: the first of `DigSites`' ranking (nearest
    row, cheapest trip) where the robot can turn full circle both where it starts digging and
    where the creep ends, since it arrives there and leaves from there; a spot by a wall is
    entered and left by manoeuvres the follower drives with only centimetres to spare. When
    none of those can be reached, `DigSites.next_spot`'s choice; when the grid sees no way
    into the digging region at all, spots ranked from inside it.

    All of that on the grid first; only when it reaches no spot, once more with the
    planner's search over headings (a gap barely wider than the robot), for at most
    `HEADING_SEARCHES` spots: a search that finds nothing costs seconds."""

    def on_grid(start: Pose, goal: tuple[float, float], goal_yaw: float) -> PlanResult:
        return planner.plan(start, goal, goal_yaw, headings=False)

    spot, result = _choose(planner, sites, pose, on_grid, tries)
    if spot is not None or result.reason.startswith("start"):
        return spot, result
    budget = [HEADING_SEARCHES]

    def over_headings(start: Pose, goal: tuple[float, float], goal_yaw: float) -> PlanResult:
        if budget[0] <= 0:
            return PlanResult((), "no more searches over headings")
        budget[0] -= 1
        return planner.plan_over_headings(start, goal, goal_yaw)

    spot, second = _choose(planner, sites, pose, over_headings, HEADING_SEARCHES)
    if spot is not None:
        return spot, second
    return None, PlanResult((), f"{result.reason}; searching over headings too: "
                                f"{second.reason}")


def _choose(planner: Planner, sites: DigSites, pose: Pose, plan: PlanFn,
            tries: int) -> tuple[DigSpot | None, PlanResult]:
    creep = sites.config.creep_m
    budget = tries
    for spot in sites.candidates(DOCK_REFERENCE, reachable_from=pose.xy):
        x, y = spot.pose.x, spot.pose.y
        if not (planner.can_spin_at(x, y) and planner.can_spin_at(x + creep, y)):
            continue
        result = plan(pose, spot.pose.xy, spot.pose.yaw)
        if result.ok:
            return spot, result
        budget -= 1
        if budget <= 0:
            break
    fallback, result = sites.next_spot(pose, reference=DOCK_REFERENCE, tries=tries, plan=plan)
    if fallback is not None:
        return fallback, result
    # The grid sees no way into the digging region: a gap barely wider than the robot,
    # which only the planner's search over headings gets through. Rank the spots from
    # inside the region instead, and let the planner try.
    last = result
    budget = tries
    for spot in sites.candidates(DIG_REFERENCE):
        x, y = spot.pose.x, spot.pose.y
        if not (planner.can_spin_at(x, y) and planner.can_spin_at(x + creep, y)):
            continue
        result = plan(pose, spot.pose.xy, spot.pose.yaw)
        if result.ok:
            return spot, result
        last = result
        budget -= 1
        if budget <= 0:
            break
    return None, last


class PlanPathToDig(Step):
    def step(self, now: float, dt: float) -> Status:
        ctx, kit = self.ctx, self.kit
        pose = kit.pose()
        if pose is None:
            return Status.lost("no pose to plan from")
        if ctx.planner is None or ctx.dig_sites is None:
            return Status.failed("no map: the obstacles were not detected")
        if ctx.dig_spot is not None:
            spot = ctx.dig_spot
            result = ctx.planner.plan(pose, spot.pose.xy, goal_yaw=spot.pose.yaw)
            if not result.ok:  # that spot has become unreachable: pick another
                ctx.dig_spot = None
        if ctx.dig_spot is None:
            found, result = choose_spot(ctx.planner, ctx.dig_sites, pose)
            if found is None and not ctx.notes.get(TIGHT_NOTE) and kit.log["obstacles"]:
                # A layout whose only way through is narrower than the robot plus the grown
                # discs: plan on the discs as detected (the planner still keeps its own
                # margin), rather than give up the run.
                ctx.notes[TIGHT_NOTE] = True
                build_map(ctx, kit.log["obstacles"], 0.0, kit.settings.partial_margin_m)
                assert ctx.planner is not None and ctx.dig_sites is not None
                log.warning("plan: no way to a digging spot around the grown obstacles; "
                            "planning on them as detected")
                found, result = choose_spot(ctx.planner, ctx.dig_sites, pose)
            if found is None:
                return Status.failed(f"no digging spot: {result.reason}")
            ctx.dig_spot = found
        if not result.ok:
            return Status.failed(result.reason)
        ctx.plan = result
        kit.log["planned"].append(("dig", result))
        ctx.notes.setdefault(OUT_M_NOTE, result.length_m)  # this leg's first plan (dig.py)
        spot = ctx.dig_spot
        return Status.done(f"to the spot at x {spot.pose.x:.2f} y {spot.pose.y:.2f}, "
                           f"{result.length_m:.1f} m")


class PlanPathHome(Step):
    def step(self, now: float, dt: float) -> Status:
        ctx, kit = self.ctx, self.kit
        pose = kit.pose()
        if pose is None:
            return Status.lost("no pose to plan from")
        if ctx.planner is None:
            return Status.failed("no map: the obstacles were not detected")
        result, dock = plan_home(ctx.planner, pose)
        ctx.notes.pop(OUT_M_NOTE, None)  # a way out cut short is no measure of the pace
        if not result.ok:
            return Status.failed(result.reason)
        ctx.plan = result
        ctx.dock = dock  # type: ignore[assignment]
        kit.log["planned"].append(("home", result))
        return Status.done(f"to the collector, {result.length_m:.1f} m")
