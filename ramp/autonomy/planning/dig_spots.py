"""Where to dig next: spots in the digging region that never repeat, nearest trip first.

Each dig leaves a trench: the bucket ladder cuts the ground just ahead of the front edge
while the robot creeps forward. A spot is the pose where digging starts, facing the far wall
(yaw 0) so the trench runs along +x. A spot is acceptable when

- its trench lies inside the digging region (x >= 4.44 m) and clear of the walls;
- the robot can turn full circle, clear of every wall by the planner's nominal margin, where
  it arrives (the spot) and where it leaves (the end of the creep): a spot too near a wall to
  turn is entered and left by reversing and arcing beside that wall at the planner's thinnest
  margin, where a few centimetres of drift in the pose estimate grazed it on long runs;
- the footprint, from the spot to the end of the creep, is clear of obstacles and walls by
  the planner's check margin, and does not stand on an earlier trench;
- its trench keeps `spacing_m` from every earlier trench (digging the same hole again yields
  little, and the robot must not drive into its own holes);
- its centre is reachable on the planner's grid.

Candidates are ranked by row (bands across the arena as long as a trench, the band nearest
the collector first, so trenches pack side by side) and within a row by the cost of the trip
from a reference point (the docking approach, since every load goes there): one Dijkstra from
the reference gives every candidate's trip.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ramp.autonomy.arena import OBSTACLE_END_X_M
from ramp.autonomy.planning.astar import dijkstra
from ramp.autonomy.planning.geometry import Pose
from ramp.autonomy.planning.planner import Planner, PlanResult

SKIP_NEAR_FAILED_M = 0.5
PlanFn = Callable[[Pose, tuple[float, float], float], PlanResult]  # start, goal, goal yaw


@dataclass(frozen=True)
class Trench:
    """An axis-aligned rectangle of dug ground: x0 <= x <= x1, y0 <= y <= y1 (m)."""

    x0: float
    y0: float
    x1: float
    y1: float

    def gap_to(self, other: Trench) -> float:
        """Distance between two rectangles (0 when they touch or overlap)."""
        dx = max(other.x0 - self.x1, self.x0 - other.x1, 0.0)
        dy = max(other.y0 - self.y1, self.y0 - other.y1, 0.0)
        return math.hypot(dx, dy)

    def overlaps(self, other: Trench) -> bool:
        return (self.x0 < other.x1 and other.x0 < self.x1 and self.y0 < other.y1
                and other.y0 < self.y1)


@dataclass(frozen=True)
class DigConfig:
    """How a dig uses ground. ASSUMPTIONS (the thesis gives no ladder size): the ladder cuts
    a strip `trench_width_m` wide, centred on the robot, from its front edge to `reach_m`
    beyond it, lengthened by the creep."""

    dig_start_x_m: float = OBSTACLE_END_X_M  # SPEC 6.1: digging region 4.44 <= x <= 7.38
    creep_m: float = 0.30  # forward creep while digging
    reach_m: float = 0.25  # cut beyond the front edge
    trench_width_m: float = 0.50  # narrower than the 0.75 m body
    spacing_m: float = 0.20  # between trenches
    wall_gap_m: float = 0.20  # between a trench and the far wall
    step_m: float = 0.10  # candidate grid


@dataclass(frozen=True)
class DigSpot:
    """Start digging at `pose` (yaw 0); the dig will leave `trench`; `trip_m` is the grid cost
    of the trip from the reference point, in metres."""

    pose: Pose
    trench: Trench
    trip_m: float


def _packed(lo: float, hi: float, pitch: float) -> list[float]:
    """As many positions from `lo` to `hi` as fit at least `pitch` apart, evenly spread."""
    if hi < lo:
        return []
    n = int(math.floor((hi - lo) / pitch + 1e-9)) + 1
    if n == 1:
        return [0.5 * (lo + hi)]
    return [lo + k * (hi - lo) / (n - 1) for k in range(n)]


class DigSites:
    """Chooses digging spots that never repeat; remembers the trenches already dug."""

    def __init__(self, planner: Planner, config: DigConfig | None = None) -> None:
        self.planner = planner
        self.config = config or DigConfig()
        self.dug: list[Trench] = []

    def trench_for(self, pose: Pose, crept_m: float | None = None) -> Trench:
        """The ground a dig from `pose` (yaw 0) cuts, creeping `crept_m` (default: planned)."""
        cfg = self.config
        creep = cfg.creep_m if crept_m is None else crept_m
        front = pose.x + self.planner.config.robot.half_length_m
        half = 0.5 * cfg.trench_width_m
        return Trench(front, pose.y - half, front + creep + cfg.reach_m, pose.y + half)

    def mark_dug(self, spot: DigSpot | Pose, crept_m: float | None = None) -> Trench:
        """Record a dig (call it with how far the robot really crept, when known)."""
        pose = spot.pose if isinstance(spot, DigSpot) else spot
        trench = self.trench_for(pose, crept_m)
        self.dug.append(trench)
        return trench

    def candidates(self, reference: tuple[float, float],
                   reachable_from: tuple[float, float] | None = None) -> list[DigSpot]:
        """Every acceptable spot, nearest row and cheapest trip from `reference` first; only
        spots reachable from `reachable_from` too, when given."""
        cfg = self.config
        planner = self.planner
        # Reachable at the smallest margin the planner accepts, from the free cell nearest the
        # reference (which may itself stand close to a wall, like the docking approach).
        arena, grid = planner.arena, planner.loosest_grid
        robot = planner.config.robot
        hl, hw = robot.half_length_m, robot.half_width_m
        ref_cell = grid.nearest_free_cell(*reference)
        if ref_cell is None:
            return []
        dist = dijkstra(grid.blocked, grid.cost, ref_cell)
        if reachable_from is not None:
            from_cell = grid.nearest_free_cell(*reachable_from)
            if from_cell is None:
                return []
            dist = np.where(np.isfinite(dijkstra(grid.blocked, grid.cost, from_cell)), dist,
                            math.inf)
        spin = robot.circumradius_m + planner.config.margin_m  # room to turn, from any wall
        x_lo = cfg.dig_start_x_m - hl  # trench starts at the front edge
        x_hi = min(arena.length - cfg.wall_gap_m - cfg.reach_m - cfg.creep_m - hl,
                   arena.length - spin - cfg.creep_m)
        y_lo = max(hw + cfg.wall_gap_m, spin)
        y_hi = min(arena.width - hw - cfg.wall_gap_m, arena.width - spin)
        xs = np.arange(math.ceil(x_lo / cfg.step_m), math.floor(x_hi / cfg.step_m) + 1) \
            * cfg.step_m
        grid_ys = np.arange(math.ceil(y_lo / cfg.step_m), math.floor(y_hi / cfg.step_m) + 1) \
            * cfg.step_m
        packed = _packed(y_lo, y_hi, cfg.trench_width_m + cfg.spacing_m)
        ys = sorted({round(float(v), 6) for v in (*grid_ys, *packed)})
        spots: list[DigSpot] = []
        for x in xs:
            for y in ys:
                x, y = float(round(x, 6)), float(y)
                cell = grid.cell_of(x, y)
                if cell is None or not math.isfinite(dist[cell]):
                    continue
                pose = Pose(x, y, 0.0)
                trench = self.trench_for(pose)
                if any(trench.gap_to(old) < cfg.spacing_m for old in self.dug):
                    continue
                body = Trench(x - hl, y - hw, x + hl + cfg.creep_m, y + hw)
                if any(body.overlaps(old) for old in self.dug):
                    continue
                creep = np.array([[x, y, 0.0], [x + 0.5 * cfg.creep_m, y, 0.0],
                                  [x + cfg.creep_m, y, 0.0]])
                if planner.clearance(creep).min() < planner.config.check_margin_m:
                    continue
                spots.append(DigSpot(pose, trench, float(dist[cell]) * grid.resolution))
        # Rows across the arena, the row nearest the collector first (short trips), so that
        # trenches pack side by side instead of scattering; in a row, the cheapest trip first.
        row = cfg.creep_m + cfg.reach_m
        # Across a row, the evenly packed places first, so the row holds as many trenches as
        # its width allows whatever order the trips rank them in.
        lanes = {round(float(v), 6) for v in packed}
        spots.sort(key=lambda s: (math.floor((s.pose.x - x_lo) / row + 1e-9),
                                  round(s.pose.y, 6) not in lanes,
                                  round(s.trip_m, 6), abs(s.pose.y - reference[1]), s.pose.x))
        return spots

    def next_spot(self, start: Pose, reference: tuple[float, float] | None = None,
                  tries: int = 6, plan: PlanFn | None = None,
                  ) -> tuple[DigSpot | None, PlanResult]:
        """The cheapest acceptable spot the planner can reach from `start`, and the plan.

        `reference` (default: `start`) ranks the trips. Spots the planner cannot reach are
        skipped, up to `tries` of them; then the last failure is returned with None. `plan`
        (start, goal, goal_yaw) -> PlanResult replaces `Planner.plan`.
        """
        plan = plan or self.planner.plan
        ref = reference if reference is not None else start.xy
        last = PlanResult((), "no acceptable digging spot is left (every one overlaps a "
                              "trench, an obstacle or a wall, or cannot be reached)")
        failed: list[tuple[float, float]] = []
        for spot in self.candidates(ref, reachable_from=start.xy):
            if tries <= 0:
                break
            if any(math.hypot(spot.pose.x - fx, spot.pose.y - fy) < SKIP_NEAR_FAILED_M
                   for fx, fy in failed):
                continue  # a spot beside one the planner could not reach fails alike
            tries -= 1
            result = plan(start, spot.pose.xy, spot.pose.yaw)
            if result.ok:
                return spot, result
            failed.append(spot.pose.xy)
            last = result
        return None, last
