"""Initial Localization and the recovery states Relevel, Rescan and Relocalize (SPEC 6.3).

- **Initial Localization** waits for the sensors (the IMU attached and the AHRS settled, the
  gimbal level, the LIDAR ready), takes level scans standing still and localizes with what
  breaks the arena's symmetry at the start: the start box (`sensing.localize_records`). When
  the localizer is lost but says where level is (an IMU whose mount shifted tilts the "level"
  scan), the AHRS takes that, the gimbal re-levels and the scans are taken once more here;
  still lost -> `lost`, and the machine's recovery takes over.
- **Relevel** levels the LIDAR from the scan itself: the level the last lost localization
  reported, or else a fresh scan's, goes to the AHRS (`level_hint`, which corrects the IMU's
  gravity and so the gimbal's set-point); then the gimbal settles level again. When the scan
  cannot say (the localizer found it tilted but not by how much) and the AHRS claims a lean
  the arena's floor never gives a standing robot, the floor is taken as level
  (`assume_level_floor`): that is an IMU whose mount shifted.
- **Rescan** takes fresh level scans (`ctx.localization_scan`).
- **Relocalize** localizes them with the AHRS yaw and the dead-reckoned pose as priors (no
  pose prior after an operator had the robot: they may have moved it anywhere); lost ->
  `lost` (the machine stops and tries again, a bounded number of times).
"""

from __future__ import annotations

import logging
import math
from typing import Any

from ramp.autonomy.executive.sensing import (
    DONE,
    FAILED,
    LEVEL_TIMEOUT_S,
    LevelScans,
    apply_fix,
    localize_records,
)
from ramp.autonomy.executive.step import Step
from ramp.autonomy.mount import angle_between
from ramp.autonomy.perception.ahrs import up_in_chassis
from ramp.autonomy.perception.pipeline import LevelHint, Localization, PoseEstimate
from ramp.statemachine import Status

log = logging.getLogger("ramp.autonomy.executive")

SENSORS_TIMEOUT_S = 20.0  # the AHRS settles in about 2 s standing still
#: More lean than this, standing still on the arena's raked floor, is the IMU's error: the
#: localizer finds the floor tilts a chassis under 5 deg, and the planner keeps the wheels
#: off rocks and craters. An IMU shift (SPEC 6.2) is 4-8 deg.
FLOOR_LEAN_DEG = 3.0
LEVEL_NOTE = "level"  # ctx.notes: the newest LevelHint a lost localization gave


def describe(pose: PoseEstimate) -> str:
    return (f"x {pose.x:.2f} y {pose.y:.2f} yaw {math.degrees(pose.yaw):.1f} deg, "
            f"confidence {pose.confidence:.2f}")


def sensors_missing(step: Step) -> str:
    """What keeps the sensors from being ready, in words ('' when they are)."""
    p = step.kit.perception
    missing = []
    if not p.imu.ready():
        missing.append(f"IMU ({p.imu.fault or 'not attached'})")
    if not p.pan_tilt.ready():
        missing.append(f"gimbal ({p.pan_tilt.fault or 'not attached'})")
    if p.lidar.state != "ready":
        missing.append(f"LIDAR ({p.lidar.state}{': ' + p.lidar.fault if p.lidar.fault else ''})")
    if not p.ahrs.settled:
        missing.append("AHRS not settled")
    if not p.leveller.settled:
        missing.append("gimbal not level")
    return "; ".join(missing)


def apply_level(step: Step, hint: LevelHint) -> None:
    """The scan's idea of level to the AHRS; the gimbal levels on the corrected attitude."""
    p = step.kit.perception
    p.ahrs.level_hint(hint.roll, hint.pitch, hint.weight, t=hint.t)
    p.leveller.level(0.0)


def assume_level_floor(step: Step) -> bool:
    """When the AHRS says the chassis, standing still, leans more than the arena's floor
    ever tilts it (`FLOOR_LEAN_DEG`), its gravity is what is wrong (an IMU whose mount
    shifted, SPEC 6.2): tell it the chassis stands level. The AHRS folds the difference into
    its mount correction, the gimbal levels on it, and what tilt is left (the floor's degree
    or so) the localizer's own re-levelling finds. True when it did. (Mid-run, with only
    level scans at hand: `pipeline.level_from_floor` needs a 3D sweep's view of the floor.)"""
    ahrs = step.kit.perception.ahrs
    lean = math.degrees(angle_between(up_in_chassis(ahrs.roll, ahrs.pitch), (0.0, 0.0, 1.0)))
    if lean <= FLOOR_LEAN_DEG or step.kit.perception.odometry.moving:
        return False
    log.warning("relevel: the AHRS says the chassis leans %.1f deg standing still on the "
                "arena's floor; taking level as the floor's", lean)
    apply_level(step, LevelHint(0.0, 0.0, 1.0, None))
    return True


class InitialLocalization(Step):
    relevels_allowed = 1

    def begin(self, now: float) -> None:
        self.scans: LevelScans | None = None
        self.relevels = 0
        self.kit.perception.leveller.level(0.0)

    def step(self, now: float, dt: float) -> Status:
        if self.scans is None:
            missing = sensors_missing(self)
            if not missing:
                self._scan(now)
            elif now - self.started_at > SENSORS_TIMEOUT_S:
                return Status.fault(f"the sensors are not ready: {missing}")
            return Status.running()
        state = self.scans.tick(now)
        if state == FAILED:
            return Status.lost(self.scans.reason)
        if state != DONE:
            return Status.running()
        loc = localize_records(self.kit, self.scans.records, start=True)
        pose = apply_fix(self.kit, loc, now)
        if pose is not None:
            return Status.done(describe(pose))
        if loc.level is not None and self.relevels < self.relevels_allowed:
            self.relevels += 1
            apply_level(self, loc.level)
            self._scan(now)
            return Status.running()
        return lost(self, loc)

    def _scan(self, now: float) -> None:
        self.scans = LevelScans(self.kit)
        self.scans.start(now)


def lost(step: Step, loc: Localization) -> Status:
    """Note what a lost localization said and answer `lost`."""
    step.ctx.notes[LEVEL_NOTE] = loc.level
    reason = loc.reason or "the localizer found no pose"
    step.kit.tracker.lose(reason)
    return Status.lost(reason)


class Relevel(Step):
    def begin(self, now: float) -> None:
        hint = self.ctx.notes.pop(LEVEL_NOTE, None)
        self.scans: LevelScans | None = None
        self.settling_since = now
        if isinstance(hint, LevelHint):
            apply_level(self, hint)
        elif not assume_level_floor(self):
            self.scans = LevelScans(self.kit)
            self.scans.start(now)

    def step(self, now: float, dt: float) -> Status:
        p = self.kit.perception
        if self.scans is not None:
            state = self.scans.tick(now)
            if state == FAILED:
                return Status.lost(self.scans.reason)
            if state != DONE:
                return Status.running()
            loc = localize_records(self.kit, self.scans.records,
                                   start=self.kit.tracker.fixes == 0)
            self.scans = None
            self.settling_since = now
            if loc.level is not None:
                apply_level(self, loc.level)
            else:
                p.leveller.level(0.0)
        if p.leveller.settled and now - self.settling_since > 0.05:
            return Status.done(f"level (AHRS mount correction {p.ahrs.correction_deg:.1f} deg)")
        if now - self.settling_since > LEVEL_TIMEOUT_S:
            return Status.lost("the gimbal does not settle level" + (
                " (beyond the tilt servo's travel)" if p.leveller.saturated else ""))
        return Status.running()


class Rescan(Step):
    def begin(self, now: float) -> None:
        self.scans = LevelScans(self.kit)
        self.scans.start(now)

    def step(self, now: float, dt: float) -> Status:
        state = self.scans.tick(now)
        if state == FAILED:
            return Status.lost(self.scans.reason)
        if state != DONE:
            return Status.running()
        self.ctx.localization_scan = list(self.scans.records)
        return Status.done(f"{len(self.scans.records)} level scans")


class Relocalize(Step):
    def step(self, now: float, dt: float) -> Status:
        records: Any = self.ctx.localization_scan
        if not records:
            return Status.lost("no scan to localize from")
        loc = localize_records(self.kit, list(records), start=self.kit.tracker.fixes == 0)
        self.ctx.localization_scan = None
        pose = apply_fix(self.kit, loc, now)
        if pose is None:
            return lost(self, loc)
        return Status.done(describe(pose))
