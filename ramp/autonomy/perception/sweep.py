"""The 3D scan as a tick task: sweep the LIDAR's tilt, keeping every scan on the way.

The thesis' 3D scanner (5.3.4) "repeatedly increases the pitch on the gimbal and takes a 2D
scan at each pre-defined angle". A UTM-30LX-EW scans 40 times a second, so instead of stopping
at each angle this sweeps the tilt slowly and keeps every scan: at 5 deg/s the scan lines lie
0.125 deg apart, a few centimetres on the ground at the obstacle region's far edge, where
stopping every degree would leave 20 cm gaps that a 15 cm rock falls through. Each scan's
record carries the servo angle reported at its own moment, so the motion costs no accuracy.

Phases: `positioning` (level at `start_deg` below the horizon at the servo's normal speed and
wait for `settled`), `sweeping` (the tilt servo's velocity limit lowered to `speed_dps`, the
leveller asked for `end_deg`, every record collected until it settles there), then `done`
(the velocity limit restored). `failed` says why a sweep gave up (the gimbal never got there
within `timeout_s`, the LIDAR stopped sending). The sweep keeps the gimbal levelled all along,
so a chassis on a slope is swept from the horizon, not from its own deck.
"""

from __future__ import annotations

import logging
import math

from ramp.autonomy.hal.interfaces import PanTilt
from ramp.autonomy.perception.gimbal import GimbalLeveller
from ramp.autonomy.perception.records import ScanRecord
from ramp.autonomy.perception.scans import ScanCollector

log = logging.getLogger("ramp.autonomy.sweep")

IDLE, POSITIONING, SWEEPING, DONE, FAILED = "idle", "positioning", "sweeping", "done", "failed"


class TiltSweep:
    """One sweep; `start(now)`, then `tick(now, dt)` until `finished`."""

    def __init__(self, leveller: GimbalLeveller, collector: ScanCollector, pan_tilt: PanTilt,
                 *, start_deg: float, end_deg: float, speed_dps: float = 5.0,
                 pan_deg: float = 0.0, timeout_s: float | None = None) -> None:
        if not all(math.isfinite(v) for v in (start_deg, end_deg, speed_dps, pan_deg)):
            raise ValueError("sweep: angles and speed must be finite numbers")
        if speed_dps <= 0.0:
            raise ValueError(f"sweep: speed {speed_dps:g} deg/s must be > 0")
        self.leveller = leveller
        self.collector = collector
        self.pan_tilt = pan_tilt
        self.start_deg = float(start_deg)
        self.end_deg = float(end_deg)
        self.speed_dps = float(speed_dps)
        self.pan_deg = float(pan_deg)
        sweep_s = abs(self.end_deg - self.start_deg) / self.speed_dps
        self.timeout_s = timeout_s if timeout_s is not None else 2.0 * sweep_s + 10.0
        self.state = IDLE
        self.reason = ""
        self.records: list[ScanRecord] = []
        self.saturated = False  # the gimbal could not reach part of the sweep
        self._began = 0.0
        self._sweep_from = math.inf
        self._normal_speed = pan_tilt.tilt.velocity_limit_dps

    @property
    def finished(self) -> bool:
        return self.state in (DONE, FAILED)

    def start(self, now: float) -> None:
        self.state = POSITIONING
        self._began = now
        self.records = []
        self.leveller.level(self.start_deg, self.pan_deg)
        self.collector.add_listener(self._keep)

    def tick(self, now: float, dt: float) -> None:
        if self.state not in (POSITIONING, SWEEPING):
            return
        if now - self._began > self.timeout_s:
            where = "its start" if self.state == POSITIONING else f"{self.end_deg:g} deg"
            self._finish(FAILED, f"the gimbal did not reach {where} within "
                                 f"{self.timeout_s:.1f} s")
            return
        self.saturated = self.saturated or self.leveller.saturated
        if self.state == POSITIONING and self.leveller.settled:
            self.pan_tilt.tilt.set_velocity_limit(self.speed_dps)
            self.leveller.level(self.end_deg, self.pan_deg)
            self._sweep_from = now
            self.state = SWEEPING
            log.info("sweep: %g -> %g deg below the horizon at %g deg/s", self.start_deg,
                     self.end_deg, self.speed_dps)
        elif self.state == SWEEPING and self.leveller.settled:
            if not self.records:
                self._finish(FAILED, "no LIDAR scan arrived during the sweep")
            else:
                self._finish(DONE, "")

    def cancel(self) -> None:
        if not self.finished:
            self._finish(FAILED, "cancelled")

    def _keep(self, record: ScanRecord) -> None:
        if self.state == SWEEPING and record.t >= self._sweep_from:
            self.records.append(record)

    def _finish(self, state: str, reason: str) -> None:
        self.state = state
        self.reason = reason
        self.collector.remove_listener(self._keep)
        if self.pan_tilt.tilt.velocity_limit_dps != self._normal_speed:
            self.pan_tilt.tilt.set_velocity_limit(self._normal_speed)
        if reason:
            log.warning("sweep: %s", reason)
