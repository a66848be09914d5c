"""Scans on demand, and what the activities make of them: level scans, localizations, the 3D
sweep.

The LIDAR serves scans on demand (GD) here, not streaming: a mission needs them only while it
localizes (a handful of level scans, standing still) and while it sweeps, and every scan
streamed for nothing costs the simulator a ray-cast and both sides a SCIP encode and decode.
A GD is answered with the first scan that *starts* after the request, so a scan asked for once
the gimbal has settled never straddles two tilts.

- `LevelScans`: wait until the wheels have stopped (`still_s` after odometry last saw them
  turn) and the gimbal sits level, then take `n` scans.
- `localize_records`: one localization, with what breaks the arena's symmetry: the start box
  before the first fix (both boxes tried when nobody said which; the one the scan fits wins),
  the AHRS yaw and the tracked pose after it.
- `apply_fix`: a confident localization corrects the AHRS yaw and fixes the tracker.
- `StopAndGoSweep`: the 3D scan of `cloud.plan_sweep` (thesis 5.3.4: "repeatedly increases
  the pitch on the gimbal and takes a 2D scan at each pre-defined angle"): level at each
  tilt, wait for the servo to settle, take one scan.
"""

from __future__ import annotations

import logging
import math

from ramp.autonomy.executive.kit import Kit
from ramp.autonomy.perception.cloud import SweepPlan
from ramp.autonomy.perception.pipeline import Localization, PoseEstimate
from ramp.autonomy.perception.records import ScanRecord

log = logging.getLogger("ramp.autonomy.executive")

WAITING, SCANNING, DONE, FAILED = "waiting", "scanning", "done", "failed"
LEVEL_TIMEOUT_S = 10.0  # the gimbal levels in well under a second; a stuck one says so
SCAN_TIMEOUT_S = 2.0  # for each scan asked for (40 come in a second)


class LevelScans:
    """`n` level scans taken standing still; `tick` until `state` is DONE or FAILED."""

    def __init__(self, kit: Kit, n: int | None = None, *, tilt_deg: float = 0.0) -> None:
        self.kit = kit
        self.n = n if n is not None else kit.settings.localize_scans
        self.tilt_deg = tilt_deg
        self.state = WAITING
        self.reason = ""
        self.records: list[ScanRecord] = []
        self._began = math.nan
        self._since = math.nan
        self._still_since: float | None = None
        self._asked_at = math.nan

    def start(self, now: float) -> None:
        self.state = WAITING
        self._began = now
        self.kit.perception.leveller.level(self.tilt_deg)

    @property
    def finished(self) -> bool:
        return self.state in (DONE, FAILED)

    def tick(self, now: float) -> str:
        p = self.kit.perception
        if self.finished:
            return self.state
        if self.state == WAITING:
            if p.odometry.moving:
                self._still_since = None
            elif self._still_since is None:
                self._still_since = now
            still = (self._still_since is not None
                     and now - self._still_since >= self.kit.settings.still_s)
            if still and p.leveller.settled and p.lidar.state == "ready":
                self.state = SCANNING
                self._since = now
                self._asked_at = now
                p.lidar.request_scan()
            elif now - self._began > LEVEL_TIMEOUT_S:
                self._fail(now)
            return self.state
        records = p.scans.since(self._since)[:self.n]
        if len(records) > len(self.records):
            self._asked_at = now  # progress: the time-out counts from the newest scan
        self.records = records
        if len(self.records) >= self.n:
            self.state = DONE
            return self.state
        p.lidar.request_scan()  # sends a GD only when none is on its way
        if now - self._asked_at > SCAN_TIMEOUT_S:
            self._fail(now)
        return self.state

    def _fail(self, now: float) -> None:
        p = self.kit.perception
        lidar = p.lidar
        if lidar.state != "ready":
            self.reason = f"the LIDAR is {lidar.state}" + (f": {lidar.fault}" if lidar.fault
                                                           else "")
        elif not p.leveller.settled:
            self.reason = "the gimbal did not settle level" + (
                " (beyond the tilt servo's travel on this slope)" if p.leveller.saturated
                else "")
        elif self.state == WAITING:
            self.reason = "the robot did not come to rest"
        else:
            self.reason = f"only {len(self.records)} of {self.n} scans arrived"
        self.state = FAILED


def localize_records(kit: Kit, records: list[ScanRecord], *, use_prior: bool = True,
                     start: bool = False) -> Localization:
    """One localization from level scans (see the module docstring for the priors)."""
    ahrs = kit.perception.ahrs
    if start:
        boxes = [kit.start_box] if kit.start_box is not None else ["left", "right"]
        found = [kit.localize(records, hint=box, yaw_prior=None, prior_pose=None)
                 for box in boxes]
        good = [loc for loc in found if not loc.lost and loc.pose is not None]
        if len(good) == 1:
            return good[0]
        if len(good) > 1:
            good.sort(key=lambda loc: -loc.pose.confidence)  # type: ignore[union-attr]
            a, b = good[0].pose, good[1].pose
            assert a is not None and b is not None
            if a.confidence - b.confidence < 0.05 and math.hypot(a.x - b.x, a.y - b.y) > 0.3:
                return Localization(None, True, (a, b), "the scan fits both start "
                                    "boxes equally well")
            return good[0]
        reasons = "; ".join(f"{box}: {loc.reason}" for box, loc in zip(boxes, found,
                                                                        strict=True))
        level = next((loc.level for loc in found if loc.level is not None), None)
        return Localization(None, True, (), f"not in the start region ({reasons})", level)
    yaw_prior = ahrs.yaw if ahrs.yaw_known else None
    prior = kit.tracker.prior if use_prior else None
    return kit.localize(records, hint=None, yaw_prior=yaw_prior, prior_pose=prior)


def apply_fix(kit: Kit, loc: Localization, now: float) -> PoseEstimate | None:
    """Take a localization: a confident pose corrects the AHRS yaw and fixes the tracker
    (and, when the localizer found the scan tilted, its level goes to the AHRS and the
    gimbal); a lost one leaves the tracker as it is (the caller decides). Returns the pose
    taken."""
    kit.log["localizations"].append(loc)
    del kit.log["localizations"][:-50]
    pose = loc.pose
    if loc.lost or pose is None:
        return None
    if loc.level is not None:  # the localizer found the scan tilted and levelled it itself
        p = kit.perception
        p.ahrs.level_hint(loc.level.roll, loc.level.pitch, loc.level.weight, t=loc.level.t)
        p.leveller.level(0.0)
    kit.perception.ahrs.correct_yaw(pose.yaw, pose.confidence)
    kit.tracker.fix(now, pose.x, pose.y, pose.yaw, pose.confidence)
    return pose


class StopAndGoSweep:
    """The tilts of a `SweepPlan`, one scan at each; `tick` until `finished`."""

    def __init__(self, kit: Kit, plan: SweepPlan, *, settle_s: float = 0.05) -> None:
        self.kit = kit
        self.plan = plan
        self.settle_s = settle_s
        self.records: list[ScanRecord] = []
        self.state = WAITING
        self.reason = ""
        self.saturated = False
        self._i = 0
        self._began = math.nan
        self._step_began = math.nan
        self._asked_at = math.nan
        self._timeout = plan.duration_s * 3.0 + 10.0

    @property
    def finished(self) -> bool:
        return self.state in (DONE, FAILED)

    def start(self, now: float) -> None:
        self._began = now
        self._i = 0
        self._go_to(0, now)

    def tick(self, now: float) -> str:
        if self.finished:
            return self.state
        p = self.kit.perception
        if now - self._began > self._timeout:
            self._finish(FAILED, f"the sweep did not finish within {self._timeout:.0f} s "
                         f"({len(self.records)} of {self.plan.scans} scans)")
            return self.state
        if p.lidar.state not in ("ready",):
            return self.state  # the driver reconnects; the timeout bounds the wait
        self.saturated = self.saturated or p.leveller.saturated
        if self.state == WAITING:
            if p.leveller.settled or (p.leveller.saturated and now - self._step_began > 1.0):
                self.state = SCANNING
                self._asked_at = now
                p.lidar.request_scan()
            return self.state
        got = p.scans.since(self._step_began)
        if got:
            self.records.append(got[0])
            self._i += 1
            if self._i >= self.plan.scans:
                self._finish(DONE, "")
            else:
                self._go_to(self._i, now)
        else:
            p.lidar.request_scan()
        return self.state

    def cancel(self) -> None:
        if not self.finished:
            self._finish(FAILED, "cancelled")

    def _go_to(self, i: int, now: float) -> None:
        self.state = WAITING
        self._step_began = now
        self.kit.perception.leveller.level(self.plan.tilts_deg[i], self.plan.pan_deg)

    def _finish(self, state: str, reason: str) -> None:
        self.state = state
        self.reason = reason
        self.kit.perception.leveller.level(0.0)  # back to level for the next localization
        if reason:
            log.warning("sweep: %s", reason)
