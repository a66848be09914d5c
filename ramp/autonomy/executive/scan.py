"""Scan for Obstacles and Detect Obstacles (thesis 5.3.4, figure 5.40).

- **Scan for Obstacles**: the 3D scan from where Prepare for Scan left the robot (standing,
  facing +x): `pipeline.plan_scan`'s tilts, which lay ground lines every `sweep_spacing_m`
  from as near as the tilt servo's travel lets the LIDAR look to 0.3 m past the obstacle
  region's far edge, taken stop-and-go (`sensing.StopAndGoSweep`).
- **Detect Obstacles**: rocks and craters from the sweep at the pose it was taken from
  (`pipeline.detect_obstacles`), then the map the planner works on: every obstacle a disc
  grown by `obstacle_margin_m` (the detector's measured errors), more for one seen only in
  part, and the ground the sweep saw too thinly to trust (`perception.coverage`), which the
  planner keeps off where it can; and the digging spots, which never repeat, on that map.
"""

from __future__ import annotations

from collections.abc import Sequence

from ramp.autonomy.executive.sensing import DONE, FAILED, StopAndGoSweep
from ramp.autonomy.executive.step import Step
from ramp.autonomy.perception.coverage import GroundCoverage
from ramp.autonomy.perception.pipeline import Obstacle, PoseEstimate, plan_scan
from ramp.autonomy.planning import ArenaMap, DigSites, Disc, Planner
from ramp.statemachine import MissionContext, Status

SWEEP_POSE_NOTE = "sweep_pose"  # ctx.notes: the PoseEstimate the sweep was taken from


TIGHT_NOTE = "tight_map"  # ctx.notes: the map was rebuilt without the margin (see plan.py)
COVERAGE_NOTE = "coverage"  # ctx.notes: GroundCoverage of every sweep so far


def coverage_of(ctx: MissionContext) -> GroundCoverage | None:
    """The floor coverage of the sweeps so far (`COVERAGE_NOTE`), None before the first."""
    coverage = ctx.notes.get(COVERAGE_NOTE)
    return coverage if isinstance(coverage, GroundCoverage) else None


def build_map(ctx: MissionContext, found: Sequence[Obstacle], margin: float,
              partial_margin: float) -> None:
    """The planner's map from detected obstacles, each disc grown by `margin` (and by
    `partial_margin` more when seen only in part), with the ground the sweeps saw too
    thinly to trust (`COVERAGE_NOTE`); the digging spots on it, keeping the trenches
    already dug."""
    rocks: list[Disc] = []
    craters: list[Disc] = []
    for o in found:
        grow = margin + (partial_margin if getattr(o, "partial", False) else 0.0)
        (rocks if o.kind == "rock" else craters).append(Disc(o.x, o.y, 0.5 * o.d + grow))
    ctx.rocks, ctx.craters = rocks, craters
    dug = list(ctx.dig_sites.dug) if ctx.dig_sites is not None else []
    coverage = coverage_of(ctx)
    poorly_seen = coverage.poorly_seen_centres() if coverage is not None else None
    ctx.planner = Planner(ArenaMap(obstacles=tuple(rocks) + tuple(craters)),
                          poorly_seen=poorly_seen)
    ctx.dig_sites = DigSites(ctx.planner)
    ctx.dig_sites.dug.extend(dug)


class ScanForObstacles(Step):
    def begin(self, now: float) -> None:
        self.sweep: StopAndGoSweep | None = None

    def step(self, now: float, dt: float) -> Status:
        kit = self.kit
        if self.sweep is None:
            tracker = kit.tracker
            pose = tracker.pose
            if pose is None:
                return Status.lost("no pose to scan from")
            if kit.perception.odometry.moving:
                kit.robot.halt_base()
                return Status.running()
            here = PoseEstimate(pose[0], pose[1], pose[2], tracker.confidence)
            plan = plan_scan(kit.config, here)
            if plan is None:
                return Status.failed(f"no ground to scan from x {pose[0]:.2f} y "
                                     f"{pose[1]:.2f}")
            self.ctx.notes[SWEEP_POSE_NOTE] = here
            self.sweep = StopAndGoSweep(kit, plan)
            self.sweep.start(now)
        state = self.sweep.tick(now)
        if state == FAILED:
            return Status.failed(f"3D scan: {self.sweep.reason}")
        if state != DONE:
            return Status.running()
        self.ctx.obstacle_scan = list(self.sweep.records)
        plan = self.sweep.plan
        return Status.done(f"{len(self.sweep.records)} scans, ground seen from "
                           f"{plan.near_m:.2f} to {plan.far_m:.2f} m ahead")

    def end(self) -> None:
        if self.sweep is not None:
            self.sweep.cancel()


class DetectObstacles(Step):
    def step(self, now: float, dt: float) -> Status:
        ctx, kit = self.ctx, self.kit
        records = ctx.obstacle_scan
        pose = ctx.notes.get(SWEEP_POSE_NOTE)
        if not records or not isinstance(pose, PoseEstimate):
            return Status.failed("no 3D scan to detect obstacles in")
        found = kit.detect(records, pose)
        ctx.notes[COVERAGE_NOTE] = kit.cover(records, pose, None)
        kit.log["obstacles"] = list(found)
        build_map(ctx, found, kit.settings.obstacle_margin_m, kit.settings.partial_margin_m)
        rocks, craters = ctx.rocks, ctx.craters
        listed = ", ".join(f"{o.kind} at ({o.x:.2f}, {o.y:.2f}) d {o.d:.2f}" for o in found)
        return Status.done(f"{len(rocks)} rocks, {len(craters)} craters"
                           + (f": {listed}" if listed else ""))
