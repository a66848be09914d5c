"""The 3D scan as a tick task: the gimbal visits the tilts of a `cloud.SweepPlan`, stop and go.

The thesis' 3D scanner (5.3.4) "repeatedly increases the pitch on the gimbal and takes a 2D
scan at each pre-defined angle"; `cloud.plan_sweep` chooses the angles so the ground lines lie
evenly spaced (4 cm) from the far edge of what is to be scanned to the nearest ground the tilt
limit lets the scanner see. For each tilt this task:

1. asks the leveller for it (`GimbalLeveller.level(tilt, pan)`): tilts are *below the
   horizon*, so the servo goes to the plan's tilt less the chassis pitch the AHRS reports
   (and whatever roll asks for), and the lines land where planned on a pitched chassis;
2. waits until the controller reports both servos at the leveller's set-point (`arrived`);
3. drops the scan under way at that moment (its beams straddle two tilts) and keeps the
   next scan that began after the arrival (`ScanRecord.started`);
4. moves on. After the last tilt the gimbal is levelled again.

Why not a continuous slow sweep keeping every scan: with the real servo timing it is slower
(0->75 deg at 5 deg/s is 15 s and 600 scans against ~10 s and ~80 scans here), its cloud is
seven times larger for the detector, and on the real sensor each scan's 18.75 ms of beams is
smeared across the moving tilt. Measured on the rig (emulators, real drivers), from the start
region: every rock and crater of 15 cm or more within 1.1 cm and 1.4 cm of diameter.

`failed` says why a sweep gave up (a tilt not reached within its time, the LIDAR silent);
`saturated` that the servo's travel clipped a tilt (the records carry the tilt reached).
The AHRS may correct itself during a sweep (an IMU that moved on its mount while parked):
`attitude_changed` says so: its records straddle the correction, and the caller scans again.
"""

from __future__ import annotations

import logging
import math

from ramp.autonomy.hal.interfaces import PanTilt
from ramp.autonomy.perception.ahrs import Ahrs
from ramp.autonomy.perception.cloud import SweepPlan, move_time
from ramp.autonomy.perception.gimbal import GimbalLeveller
from ramp.autonomy.perception.records import ScanRecord
from ramp.autonomy.perception.scans import ScanCollector

log = logging.getLogger("ramp.autonomy.sweep")

IDLE, MOVING, SCANNING, DONE, FAILED = "idle", "moving", "scanning", "done", "failed"

#: Reported servo angle within this of the set-point: arrived (the controller reports the
#: pulse it sends; it lands exactly on the target).
ARRIVED_DEG = 1e-3
#: Beyond its planned move, how long a tilt may take to arrive, and a scan to come, s.
SLACK_S = 1.0


class Sweep:
    """One stop-and-go 3D scan; `start(now)`, then `tick(now, dt)` until `finished`."""

    def __init__(self, leveller: GimbalLeveller, collector: ScanCollector, pan_tilt: PanTilt,
                 plan: SweepPlan, *, ahrs: Ahrs | None = None, dwell_s: float = 0.0) -> None:
        if not plan.tilts_deg:
            raise ValueError("sweep: the plan has no tilts")
        if not (math.isfinite(dwell_s) and dwell_s >= 0.0):
            raise ValueError(f"sweep: dwell {dwell_s!r} s must be >= 0")
        self.leveller = leveller
        self.collector = collector
        self.pan_tilt = pan_tilt
        self.plan = plan
        self.ahrs = ahrs
        self.dwell_s = dwell_s  # extra wait after arrival (a servo that lags its controller)
        self.state = IDLE
        self.reason = ""
        self.records: list[ScanRecord] = []
        self.saturated = False
        self.attitude_changed = False
        self.began = math.nan
        self.ended = math.nan
        self._i = 0
        self._deadline = math.inf
        self._arrived: float | None = None
        self._correction0: object = None

    @property
    def finished(self) -> bool:
        return self.state in (DONE, FAILED)

    @property
    def tilt_deg(self) -> float:
        """The plan's tilt being visited now (below the horizon)."""
        return self.plan.tilts_deg[min(self._i, len(self.plan.tilts_deg) - 1)]

    def start(self, now: float) -> None:
        self.records = []
        self.began = now
        self._i = 0
        self._correction0 = self.ahrs.correction if self.ahrs is not None else None
        self.collector.add_listener(self._keep)
        self._go(now, from_deg=self.leveller.wanted_tilt_deg)

    def tick(self, now: float, dt: float) -> None:
        if self.state not in (MOVING, SCANNING):
            return
        self.saturated = self.saturated or self.leveller.saturated
        if now > self._deadline:
            what = "reach" if self.state == MOVING else "get a scan at"
            self._finish(now, FAILED, f"could not {what} {self.tilt_deg:g} deg below the "
                                      f"horizon (tilt {self._i + 1} of {self.plan.scans})")
            return
        if self.state == MOVING and self._on_target():
            self._arrived = now + self.dwell_s
            self._deadline = now + self.dwell_s + SLACK_S
            self.state = SCANNING

    def cancel(self, now: float) -> None:
        if not self.finished:
            self._finish(now, FAILED, "cancelled")

    # -- internals -------------------------------------------------------------------------------
    def _go(self, now: float, from_deg: float) -> None:
        tilt = self.tilt_deg
        pan_from = self.leveller.wanted_pan_deg
        self.leveller.level(tilt, self.plan.pan_deg)
        t_servo, p_servo = self.pan_tilt.tilt, self.pan_tilt.pan
        move = max(move_time(tilt - from_deg, t_servo.velocity_limit_dps,
                             t_servo.acceleration_dps2),
                   move_time(self.plan.pan_deg - pan_from, p_servo.velocity_limit_dps,
                             p_servo.acceleration_dps2))
        self._deadline = now + move + SLACK_S
        self._arrived = None
        self.state = MOVING

    def _on_target(self) -> bool:
        target = self.leveller.target
        pan, tilt = self.pan_tilt.angles()
        if target is None or pan is None or tilt is None:
            return False
        want = self.leveller.setpoint()
        if max(abs(want[0] - target[0]), abs(want[1] - target[1])) > self.leveller.deadband_deg:
            return False  # the leveller has not sent this tilt yet
        return abs(pan - target[0]) <= ARRIVED_DEG and abs(tilt - target[1]) <= ARRIVED_DEG

    def _keep(self, record: ScanRecord) -> None:
        if self.state != SCANNING or self._arrived is None:
            return
        started = record.started if record.started is not None else record.t
        if started < self._arrived:
            return  # under way when the gimbal arrived: its beams straddle two tilts
        self.records.append(record)
        self._i += 1
        if self._i >= len(self.plan.tilts_deg):
            self._finish(record.t, DONE, "")
        else:
            self._go(record.t, from_deg=self.plan.tilts_deg[self._i - 1])

    def _finish(self, now: float, state: str, reason: str) -> None:
        self.state = state
        self.reason = reason
        self.ended = now
        self.collector.remove_listener(self._keep)
        if self.ahrs is not None and self.ahrs.correction != self._correction0:
            self.attitude_changed = True
        self.leveller.level(0.0, 0.0)
        if reason:
            log.warning("sweep: %s", reason)
