"""Docking: line the rear up with the collector, then back straight onto the x = 0 wall.

MARTE dumps over its rear into the collector bin behind the x = 0 wall, centred at
y = 1.94 (SPEC 6.1), and its docking buttons sit on the rear corners. So the robot ends facing
+x (yaw 0) with its rear edge centred on the collector and touching the wall. It gets there
from an **approach pose** straight in front of the collector, facing +x, by reversing along
a straight line: the footprint stays square to the wall the whole way and arrives centred,
and the follower has the whole straight to correct a small lateral error before contact.

The longer the straight, the better the alignment, but its front end reaches into the
obstacle region; so approaches are offered longest first and the first one the planner can
reach (footprint clear, room to turn into it or a manoeuvre that gets there) is used.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ramp.autonomy.arena import COLLECTOR_WIDTH_M, COLLECTOR_Y_M
from ramp.autonomy.planning.geometry import Pose
from ramp.autonomy.planning.path import Path
from ramp.autonomy.planning.planner import Planner, PlanResult

# Straight reverse lengths tried, longest first (m of travel from the approach to the wall).
REVERSE_LENGTHS_M = (1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1)
HEADING_SEARCHES = 3  # approaches tried with the search over headings when the grid fails


@dataclass(frozen=True)
class DockApproach:
    """Where the straight reverse starts, the reverse leg itself, and the docked pose."""

    approach: Pose  # yaw 0: rear towards the collector wall
    reverse: Path  # driven backwards from the approach to `docked`
    docked: Pose  # rear edge on the x = 0 wall, centred on the collector


def docking_approaches(planner: Planner, *, collector_y: float = COLLECTOR_Y_M,
                       lengths: Sequence[float] = REVERSE_LENGTHS_M) -> list[DockApproach]:
    """Approaches whose whole straight reverse keeps the footprint clear of obstacles and of
    the side walls (the x = 0 wall is the target) by the planner's smallest check margin,
    longest first."""
    robot = planner.config.robot
    half_collector = 0.5 * COLLECTOR_WIDTH_M
    if robot.half_width_m > half_collector:
        raise ValueError("the robot's rear is wider than the collector")
    docked = Pose(robot.half_length_m, collector_y, 0.0)
    out = []
    for length in lengths:
        approach = Pose(docked.x + length, collector_y, 0.0)
        points = np.linspace([approach.x, approach.y], [docked.x, docked.y],
                             max(2, round(length / planner.config.waypoint_spacing_m) + 1))
        leg = Path(points, reverse=True, final_yaw=None)
        clear, _pose = planner.legs_clearance([leg], 0.0, x0_wall=False)
        if clear >= 0.5 * planner.config.min_margin_m:
            out.append(DockApproach(approach, leg, docked))
    return out


def plan_to_dock(planner: Planner, start: Pose, *, collector_y: float = COLLECTOR_Y_M,
                 headings: bool = True) -> tuple[PlanResult, DockApproach | None]:
    """Plan from `start` to the first reachable approach; append the reverse leg.

    Returns the plan (its last leg is the straight reverse) and the approach used, or a
    failed plan with the reason and None. `headings` False: the grid alone, never the
    planner's search over headings.
    """
    approaches = docking_approaches(planner, collector_y=collector_y)
    if not approaches:
        return PlanResult((), f"no straight approach to the collector at y = {collector_y:.2f}"
                              " keeps the footprint clear of obstacles"), None
    # Every approach on the grid first; the search over headings (seconds where it finds
    # nothing) only when the grid reaches none, and then for the first few it may help.
    grid_reasons: list[str] = []
    for dock in approaches:
        result = planner.plan(start, dock.approach.xy, goal_yaw=dock.approach.yaw,
                              headings=False)
        if result.ok:
            return _with_reverse(result, dock), dock
        grid_reasons.append(result.reason)
    why = grid_reasons[-1]
    hopeful = [dock for dock, reason in zip(approaches, grid_reasons, strict=True)
               if not reason.startswith(("goal:", "start"))]
    for dock in hopeful[:HEADING_SEARCHES if headings else 0]:
        result = planner.plan_over_headings(start, dock.approach.xy, goal_yaw=dock.approach.yaw)
        if result.ok:
            return _with_reverse(result, dock), dock
        why = f"{grid_reasons[-1]}; searching over headings too: {result.reason}"
    return PlanResult((), f"cannot reach any docking approach: {why}"), None


def _with_reverse(result: PlanResult, dock: DockApproach) -> PlanResult:
    return PlanResult(result.legs + (dock.reverse,), "", result.expanded,
                      result.min_clearance_m, result.margin_m)
