"""A second, closer look at the obstacle region, once per run, on the way out to dig.

The 3D scan from the start region sees the far half of the obstacle region from 2-3.5 m
away, where a rock at SPEC 6.1's smallest (10 cm across, 5 cm tall) gives the detector a
handful of returns: the perception's campaign guarantees every rock and crater of 15 cm or
more from there, not the smaller ones, and a 10 cm rock it missed is one the planner drove
into (seed 37, `gyro-drift`). So the first time a crossing out stands (for a fix) inside the
obstacle region, at `LOOK_X_M`, facing the digging region within `MAX_YAW_DEG` (the gimbal
pans the rest), it sweeps again: `pipeline.plan_scan` facing +x, from there to 0.3 m past the
region, the same stop-and-go sweep as Scan for Obstacles, at a third of the distance. What it
finds joins the map (`merge_obstacles`: the same rock seen twice is kept once, the larger
disc at the closer look's centre), the planner and the digging spots are rebuilt, and the
crossing checks its way on against the new map. About 20 s, once.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

from ramp.autonomy.executive.scan import COVERAGE_NOTE, TIGHT_NOTE, build_map, coverage_of
from ramp.autonomy.executive.sensing import DONE, FAILED, StopAndGoSweep
from ramp.autonomy.executive.step import Step
from ramp.autonomy.perception.pipeline import Obstacle, PoseEstimate, plan_scan
from ramp.autonomy.planning import Pose

log = logging.getLogger("ramp.autonomy.executive")

LOOK_NOTE = "looked_again"  # ctx.notes: the closer look was taken (or could not be)
LOOK_X_M = (2.2, 3.6)  # where the robot's centre stands for it
MAX_YAW_DEG = 80.0  # the gimbal pans up to 90 deg; 10 kept for the sweep's own pan
RUNNING = "running"


def wants_look(step: Step, pose: Pose) -> bool:
    """True when a crossing out should stop here for the closer look."""
    return (not step.ctx.notes.get(LOOK_NOTE)
            and LOOK_X_M[0] <= pose.x <= LOOK_X_M[1]
            and abs(math.degrees(pose.yaw)) <= MAX_YAW_DEG)


def merge_obstacles(old: Sequence[Obstacle], new: Sequence[Obstacle]) -> list[Obstacle]:
    """The map's obstacles after another look: each new one that is an old one seen again (the
    same kind, centres closer than the larger radius) replaces it with the larger diameter
    at the new centre (the closer look places it better; the planner keeps off the larger);
    the others are added. Old ones the new look did not cover stay."""
    merged = list(old)
    for o in new:
        same = [k for k, m in enumerate(merged)
                if m.kind == o.kind and math.hypot(m.x - o.x, m.y - o.y) < 0.5 * max(m.d, o.d)]
        if not same:
            merged.append(o)
            continue
        k = same[0]
        d = max(merged[k].d, o.d)
        merged[k] = o if o.d >= d else Obstacle(o.kind, o.x, o.y, d, o.height, o.points,
                                                o.partial)
    return merged


class LookAgain:
    """The closer look, from where the robot stands: `start`, `tick` until it is not
    RUNNING, then `finish` puts what it found on the map."""

    def __init__(self, step: Step) -> None:
        self.step = step
        self.sweep: StopAndGoSweep | None = None
        self.pose: PoseEstimate | None = None

    def start(self, now: float) -> bool:
        """Begin the sweep; False (and the look marked taken) when there is nothing to
        sweep from here."""
        kit, ctx = self.step.kit, self.step.ctx
        ctx.notes[LOOK_NOTE] = True
        here = kit.tracker.pose
        if here is None:
            return False
        x, y, yaw = here
        pan = max(-MAX_YAW_DEG, min(MAX_YAW_DEG, -math.degrees(yaw)))
        self.pose = PoseEstimate(x, y, yaw, kit.tracker.confidence)
        plan = plan_scan(kit.config, self.pose, pan_deg=pan)
        if plan is None:
            return False
        self.sweep = StopAndGoSweep(kit, plan)
        self.sweep.start(now)
        return True

    def tick(self, now: float) -> str:
        if self.sweep is None:
            return FAILED
        state = self.sweep.tick(now)
        return state if state in (DONE, FAILED) else RUNNING

    def finish(self) -> list[Obstacle]:
        """The sweep's obstacles merged into the map (planner and digging spots rebuilt);
        returns those it found that the map did not have."""
        kit, ctx = self.step.kit, self.step.ctx
        if self.sweep is None or self.sweep.state != DONE or self.pose is None:
            return []
        found = kit.detect(self.sweep.records, self.pose)
        ctx.notes[COVERAGE_NOTE] = kit.cover(self.sweep.records, self.pose, coverage_of(ctx))
        old = list(kit.log["obstacles"])
        merged = merge_obstacles(old, found)
        kit.log["obstacles"] = merged
        tight = bool(ctx.notes.get(TIGHT_NOTE))
        build_map(ctx, merged, 0.0 if tight else kit.settings.obstacle_margin_m,
                  kit.settings.partial_margin_m)
        added = merged[len(old):]
        log.info("look again from x %.2f y %.2f: %d obstacle(s), %d new%s", self.pose.x,
                 self.pose.y, len(found), len(added),
                 "".join(f"; {o.kind} at ({o.x:.2f}, {o.y:.2f}) d {o.d:.2f}" for o in added))
        return added

    def cancel(self) -> None:
        if self.sweep is not None:
            self.sweep.cancel()
