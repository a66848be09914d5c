"""Driving a plan: the follower on `base.drive`, with short stops to localize on the way.

`PlanDriver` drives the legs of a `PlanResult` with `PathFollower` (pure pursuit, turns in
place), from the tracked pose (the last fix moved by odometry and the gyro, `pose.py`). The
localizer needs the robot standing still, so it stops to localize:

- after `relocalize_every_m` of driving since the last fix (mid-stretch);
- before a turn in place once it has moved since the last fix: a turn sweeps the footprint's
  corners wide, and the planner checked that sweep at the corner the plan put it, so the
  robot should know where it really is before it turns;
- before a leg driven backwards (docking) and at the end when asked (`final_fix`);
- where the caller wants to look around (`look`): after that fix it pauses (`paused`) until
  the caller calls `resume`, which checks the way on as below.

After a fix before a turn, after a fix that puts the robot more than `REPLAN_OFF_M` off the
leg it drives, and after it went off the path, it checks the way on from where the robot
really is: the turn's sweep from the true pose (the follower stops a few millimetres off the
planned corner, and a turn near a wall has little more room than that). The rest of the plan,
joined from there (`rejoin`), is kept when it passes the planner's exact check from there
(`check`, `Planner.accepts`); otherwise it plans again (`replan`): on the grid, then with the
search over headings (seconds of work where it finds nothing). Keeping a plan that still
checks matters beyond the saved work: a new plan from beside a spot with no room to turn may
back away to where the robot can turn and come in again the same way, and arrive beside it
again, for ever. A fix mid-stretch that agrees with the plan keeps it, so the route does not
change its mind at every stop. A fix that fails is tried once more (re-levelled first when the
localizer says where level is); still lost -> `lost`, and it never drives without a pose: the
robot stops first.

Drive commands go out when they change and at least every `resend_s` while driving (which
also feeds the backend's watchdog); a stop goes out whenever it stops.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence

import numpy as np

from ramp.autonomy.executive.kit import Kit
from ramp.autonomy.executive.localize import apply_level, assume_level_floor, describe, lost
from ramp.autonomy.executive.sensing import (
    DONE,
    FAILED,
    LevelScans,
    apply_fix,
    localize_records,
)
from ramp.autonomy.executive.step import Step
from ramp.autonomy.planning import FollowerConfig, Path, PathFollower, PlanResult, Pose
from ramp.autonomy.planning.follower import DONE as FOLLOWER_DONE
from ramp.autonomy.planning.follower import FOLLOWING, OFF_PATH, TURNING
from ramp.statemachine import Status

log = logging.getLogger("ramp.autonomy.executive")

Replan = Callable[[Pose, bool], PlanResult]  # from here; may it search over headings
Check = Callable[[Sequence[Path], float], bool]  # legs, start yaw -> clear enough to drive
Look = Callable[[Pose], bool]  # stop here, fix and pause for the caller (`look.py`)?

DRIVING, FIXING, PAUSED = "driving", "fixing", "paused"
TURN_FIX_M = 0.25  # moved at least this far since the last fix: localize before turning
LOW_CONFIDENCE = 0.6  # below this (and above the mission's 0.5), stop and localize
RESEND_S = 0.25
REPLAN_OFF_M = 0.03  # a fix this far from the leg being driven: plan again from there


class PlanDriver:
    """Drives `legs` (see the module docstring); `tick` returns a Status."""

    def __init__(self, step: Step, legs: Sequence[Path], *, replan: Replan | None = None,
                 final_fix: bool = False, fix_before_reverse: bool = False,
                 config: FollowerConfig | None = None, max_replans: int | None = None,
                 relocalize_every_m: float | None = None, check: Check | None = None,
                 look: Look | None = None) -> None:
        if not legs:
            raise ValueError("nothing to drive: the plan has no legs")
        self.step_ = step
        self.kit: Kit = step.kit
        self.legs = list(legs)
        self.replan = replan
        self.check = check
        self.look = look
        self._for_look = False
        self.final_fix = final_fix
        self.fix_before_reverse = fix_before_reverse
        self.config = config or self.kit.follower_config()
        s = self.kit.settings
        self.max_replans = s.max_replans if max_replans is None else max_replans
        self.every_m = s.relocalize_every_m if relocalize_every_m is None else relocalize_every_m
        self.replans = 0
        self.fixes = 0
        self.state = DRIVING
        self._leg = 0
        self._follower = PathFollower(self.legs[0], self.config)
        self._scans: LevelScans | None = None
        self._final = False
        self._retried = False
        self._off_path = False
        self._before_turn = False
        self._last_status = ""
        self._sent: tuple[int, float] | None = None
        self._sent_at = -math.inf

    @property
    def leg(self) -> Path:
        return self.legs[self._leg]

    @property
    def paused(self) -> bool:
        """Stopped, localized, and waiting for the caller's `resume` (see `look`)."""
        return self.state == PAUSED

    def resume(self, now: float) -> Status:
        """Drive on after a pause: the way on checked from where the robot stands, against
        whatever map `replan` and `check` now use."""
        self.state = DRIVING
        pose = self.kit.tracker.estimate()
        if pose is None:
            return Status.lost(self.kit.tracker.lost_reason or "no pose")
        legs = self._plan_from(pose)
        if isinstance(legs, str):
            return Status.failed(f"no plan from x {pose.x:.2f} y {pose.y:.2f}: {legs}")
        self._set_legs(legs)
        return Status.running()

    def tick(self, now: float) -> Status:
        if self.state == FIXING:
            return self._fixing(now)
        if self.state == PAUSED:
            return Status.running()
        kit = self.kit
        pose = kit.tracker.estimate()
        if pose is None:
            self._halt()
            return Status.lost(kit.tracker.lost_reason or "no pose")
        if kit.tracker.confidence < LOW_CONFIDENCE and kit.tracker.distance_m > 0.05:
            return self._fix(now)
        cmd = self._follower.update(pose)
        status = cmd.status
        if status == FOLLOWER_DONE:
            return self._next_leg(now)
        if status == OFF_PATH:
            self._halt()
            if self.replan is None or self.replans >= self.max_replans:
                return Status.failed(f"off the path by {abs(cmd.cross_track_m):.2f} m")
            self.replans += 1
            self._off_path = True
            return self._fix(now)
        if status == FOLLOWING and self.look is not None and self.look(pose):
            self._for_look = True
            return self._fix(now)
        moved = kit.tracker.distance_m
        starting_turn = status == TURNING and self._last_status != TURNING
        if (status == FOLLOWING and moved >= self.every_m) or (
                starting_turn and moved >= TURN_FIX_M):
            self._last_status = ""
            self._before_turn = starting_turn
            return self._fix(now)
        self._last_status = status
        self._drive(cmd.speed, cmd.direction, now)
        return Status.running()

    def cancel(self) -> None:
        self.kit.robot.moving = False

    # -- pieces --------------------------------------------------------------------------------
    def _next_leg(self, now: float) -> Status:
        self._leg += 1
        if self._leg >= len(self.legs):
            self._halt()
            if self.final_fix:
                self._final = True
                return self._fix(now)
            return Status.done(f"arrived ({self.fixes} fixes on the way)")
        self._follower = PathFollower(self.leg, self.config)
        self._last_status = ""
        if self.leg.reverse and self.fix_before_reverse and self.kit.tracker.distance_m > 0.05:
            self._halt()
            return self._fix(now)
        return self.tick(now)

    def _fix(self, now: float) -> Status:
        self._halt()
        self.state = FIXING
        self._retried = False
        self._scans = LevelScans(self.kit)
        self._scans.start(now)
        return Status.running()

    def _fixing(self, now: float) -> Status:
        assert self._scans is not None
        state = self._scans.tick(now)
        if state == FAILED:
            return Status.lost(self._scans.reason)
        if state != DONE:
            return Status.running()
        loc = localize_records(self.kit, self._scans.records)
        pose = apply_fix(self.kit, loc, now)
        if pose is None:
            if not self._retried:
                self._retried = True
                if loc.level is not None:
                    apply_level(self.step_, loc.level)
                else:
                    assume_level_floor(self.step_)
                self._scans = LevelScans(self.kit)
                self._scans.start(now)
                return Status.running()
            return lost(self.step_, loc)
        self.fixes += 1
        log.debug("drive: fixed at %s", describe(pose))
        if self._final:
            return Status.done(f"arrived at {describe(pose)}")
        self.state = DRIVING
        if self._for_look:
            self._for_look = False
            self.state = PAUSED
            return Status.running()
        here = Pose(pose.x, pose.y, pose.yaw)
        if self.replan is not None and (self._off_path or self._before_turn
                                        or off_track(self.leg, here) > REPLAN_OFF_M):
            self._off_path = self._before_turn = False
            legs = self._plan_from(here)
            if isinstance(legs, str):
                return Status.failed(f"no plan from {describe(pose)}: {legs}")
            self._set_legs(legs)
        return Status.running()

    def _set_legs(self, legs: list[Path]) -> None:
        self.legs = legs
        self._leg = 0
        self._follower = PathFollower(self.leg, self.config)
        self._last_status = ""

    def _plan_from(self, here: Pose) -> list[Path] | str:
        """Legs from `here`: the old plan rejoined from here if it passes the exact check
        from here, else a new plan on the grid, else one searched over headings too; or why
        there is none."""
        assert self.replan is not None
        legs = rejoin(self.legs[self._leg:], here)
        if self.check is not None and legs and self.check(legs, here.yaw):
            return legs
        result = self.replan(here, False)
        if result.ok:
            return list(result.legs)
        result = self.replan(here, True)
        return list(result.legs) if result.ok else result.reason

    def _drive(self, speed: int, direction: float, now: float) -> None:
        robot = self.kit.robot
        if speed == 0:
            if self._sent != (0, 0.0):
                self._halt()
            return
        if self._sent != (speed, direction) or now - self._sent_at >= RESEND_S:
            robot.drive(speed, direction)
            self._sent = (speed, direction)
            self._sent_at = now

    def _halt(self) -> None:
        if self._sent != (0, 0.0):
            self.kit.robot.halt_base()
            self._sent = (0, 0.0)
        self.kit.robot.moving = False


def off_track(leg: Path, pose: Pose) -> float:
    """Distance (m) from a pose to the polyline of a leg."""
    pts = leg.points
    p = np.array([pose.x, pose.y])
    if len(pts) < 2:
        return float(np.hypot(*(pts[0] - p)))
    a, b = pts[:-1], pts[1:]
    ab = b - a
    length2 = np.maximum((ab * ab).sum(axis=1), 1e-12)
    t = np.clip(((p - a) * ab).sum(axis=1) / length2, 0.0, 1.0)
    nearest = a + ab * t[:, None]
    return float(np.hypot(*(nearest - p).T).min())


def rejoin(legs: Sequence[Path], pose: Pose) -> list[Path]:
    """The rest of `legs` (the first being driven) from `pose`: straight to the first
    waypoint of the first leg ahead of the nearest point on it, then on as planned."""
    if not legs:
        return []
    first = legs[0]
    pts = first.points
    p = np.array([pose.x, pose.y])
    if len(pts) < 2:
        ahead = pts
    else:
        a, b = pts[:-1], pts[1:]
        ab = b - a
        length2 = np.maximum((ab * ab).sum(axis=1), 1e-12)
        t = np.clip(((p - a) * ab).sum(axis=1) / length2, 0.0, 1.0)
        k = int(np.argmin(np.hypot(*(a + ab * t[:, None] - p).T)))
        ahead = pts[k + 1:]
    if len(ahead) and float(np.hypot(*(ahead[0] - p))) < 0.01:
        ahead = ahead[1:]
    if not len(ahead):
        ahead = pts[-1:]
    joined = Path(np.vstack([p, ahead]), reverse=first.reverse, final_yaw=first.final_yaw)
    return [joined, *legs[1:]]
