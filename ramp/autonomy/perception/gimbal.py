"""Gimbal levelling: keep the LIDAR's scan plane level with the horizon as the chassis tilts.

The thesis' gimbal component (5.3.4) "makes the pan/tilt keep the LIDAR at a constant
orientation versus gravity, even as the platform moves across the uneven terrain". Here it is
a tick task between the AHRS and the pan/tilt driver:

- `level(tilt_deg=0, pan_deg=0)` asks for the scanner's forward beam (step 540) to point
  `tilt_deg` below the horizon (0: level; the 3D sweep asks for more) with the head panned
  `pan_deg` from the chassis' forward axis;
- every tick it solves for the servo tilt that gives that elevation on the chassis the AHRS
  reports (roll and pitch, the LIDAR's own mount rotation, the pan), clamps it to the servo's
  limits and sends it when it moved by more than `deadband_deg`; the servo controller then
  moves at its velocity limit and acceleration (`autonomy.yaml`), which bound how fast the
  gimbal can follow;
- `saturated` says the wanted attitude is outside the servo's travel (the chassis tilts more
  than the gimbal can take back); `settled` says the reported servo angles have sat on the
  set-point for `settle_s`, so a scan taken now is what was asked for;
- `correct(d_tilt_deg)` adds a trim to the tilt set-point: the re-leveller's correction when
  the scan itself shows the LIDAR is not where the AHRS thinks (a shifted IMU mount).

With pan and tilt only, the beam ahead can be levelled exactly; the scan plane keeps the
chassis' roll about that beam, which the scan records carry (their roll and pitch come from
the AHRS), so the localizer and the 3D cloud still place every point right.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from ramp.autonomy.hal.interfaces import PanTilt
from ramp.autonomy.mount import Mount

log = logging.getLogger("ramp.autonomy.gimbal")

Attitude = Callable[[], tuple[float, float]]  # (roll, pitch) of the chassis, rad
_TWO_PI = 2 * math.pi


def servo_tilt_for(elevation_down: float, roll: float, pitch: float, pan: float,
                   lidar_rotation: tuple[tuple[float, float, float], ...] | None = None,
                   near: float = 0.0) -> float:
    """The servo tilt (rad) that points the scanner's forward beam `elevation_down` (rad)
    below the horizon on a chassis at `roll`, `pitch` with the head panned `pan` (rad).

    The beam's direction is Rz(pan) Ry(tilt) m in the chassis frame (m: the scanner's
    forward axis through its mount rotation); its height component in the world is
    P cos(tilt) + Q sin(tilt) + K, set equal to -sin(elevation_down) and solved in closed
    form. Of the two solutions the one nearest `near` is returned; when none exists (a tilt
    beyond reach) the one that comes closest.
    """
    if lidar_rotation is None:
        m0, m1, m2 = 1.0, 0.0, 0.0
    else:
        m0, m1, m2 = lidar_rotation[0][0], lidar_rotation[1][0], lidar_rotation[2][0]
    # up = up_in_chassis(roll, pitch), written out (one cos of the pitch, the same value).
    cos_p = math.cos(pitch)
    u0, u1, u2 = -math.sin(pitch), cos_p * math.sin(roll), cos_p * math.cos(roll)
    c, s = math.cos(pan), math.sin(pan)
    v0, v1, v2 = c * u0 + s * u1, -s * u0 + c * u1, u2  # up in the panned frame
    p_ = v0 * m0 + v2 * m2
    q_ = v0 * m2 - v2 * m0
    k_ = v1 * m1
    r = math.hypot(p_, q_)
    phi = math.atan2(q_, p_)
    ratio = (-math.sin(elevation_down) - k_) / r if r > 0.0 else 0.0
    spread = math.acos(max(-1.0, min(1.0, ratio)))
    # The root nearest `near`, the first on a tie (as min() over the two would pick).
    first = math.remainder(phi + spread, _TWO_PI)
    second = math.remainder(phi - spread, _TWO_PI)
    return second if abs(second - near) < abs(first - near) else first


class GimbalLeveller:
    """Keeps the LIDAR at a set elevation versus gravity; a scheduler task (`tick`)."""

    def __init__(self, pan_tilt: PanTilt, attitude: Attitude, lidar_mount: Mount | None = None,
                 *, deadband_deg: float = 0.05, tolerance_deg: float = 0.25,
                 settle_s: float = 0.1) -> None:
        self.pan_tilt = pan_tilt
        self.attitude = attitude
        self.lidar_rotation = (lidar_mount or Mount()).rotation()
        self.deadband_deg = deadband_deg
        self.tolerance_deg = tolerance_deg
        self.settle_s = settle_s
        self.wanted_tilt_deg = 0.0  # below the horizon
        self.wanted_pan_deg = 0.0  # from the chassis' forward axis
        self.correction_deg = 0.0  # trim added to the tilt (re-levelling)
        self.target: tuple[float, float] | None = None  # (pan, tilt) servo degrees sent
        self.saturated = False
        self.active = True  # False: hold still, send nothing (a test or a manual move)
        self._on_target_since: float | None = None
        self._last_change = -math.inf
        self._engaged = False
        self.settled = False

    # -- what the mission asks ----------------------------------------------------------------
    def level(self, tilt_deg: float = 0.0, pan_deg: float = 0.0) -> None:
        """Point the scanner `tilt_deg` below the horizon (0 = level), panned `pan_deg`."""
        for label, v in (("tilt", tilt_deg), ("pan", pan_deg)):
            if not math.isfinite(v):
                raise ValueError(f"gimbal: {label} must be a finite angle, got {v!r}")
        if (tilt_deg, pan_deg) != (self.wanted_tilt_deg, self.wanted_pan_deg):
            self.wanted_tilt_deg, self.wanted_pan_deg = float(tilt_deg), float(pan_deg)
            self.settled = False
            self._on_target_since = None

    def correct(self, d_tilt_deg: float) -> None:
        """Add `d_tilt_deg` to the tilt trim (positive: further down)."""
        if not math.isfinite(d_tilt_deg):
            raise ValueError("gimbal: a correction must be a finite angle")
        self.correction_deg += d_tilt_deg
        self.settled = False
        self._on_target_since = None
        log.info("gimbal: tilt trim now %+.2f deg", self.correction_deg)

    def setpoint(self) -> tuple[float, float, bool]:
        """(pan, tilt, saturated): servo degrees for the wanted elevation on the chassis as
        the AHRS reports it now, clamped to the servos' limits."""
        roll, pitch = self.attitude()
        want = math.radians(self.wanted_tilt_deg + self.correction_deg)
        pan = math.radians(self.wanted_pan_deg)
        near = math.radians(self.target[1]) if self.target is not None else want
        tilt = math.degrees(servo_tilt_for(want, roll, pitch, pan, self.lidar_rotation, near))
        pan_c = self.pan_tilt.pan.clamp(self.wanted_pan_deg)
        tilt_c = self.pan_tilt.tilt.clamp(tilt)
        saturated = abs(tilt_c - tilt) > 1e-9 or abs(pan_c - self.wanted_pan_deg) > 1e-9
        return pan_c, tilt_c, saturated

    # -- the task ------------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        if not self.active or not self.pan_tilt.ready():
            self._on_target_since = None
            self.settled = False
            if not self.pan_tilt.ready():
                self._engaged = False
            return
        pan, tilt, saturated = self.setpoint()
        if saturated and not self.saturated:
            log.warning("gimbal: %.1f deg below the horizon is beyond the tilt servo's "
                        "%g..%g deg on this slope", self.wanted_tilt_deg + self.correction_deg,
                        *self.pan_tilt.tilt.limits)
        self.saturated = saturated
        moved = self.target is None or max(abs(pan - self.target[0]),
                                           abs(tilt - self.target[1])) > self.deadband_deg
        if moved or not self._engaged:
            self.pan_tilt.point(pan, tilt)
            if not self._engaged:
                self.pan_tilt.engage(True)
                self._engaged = True
            if self.target is None or max(abs(pan - self.target[0]),
                                          abs(tilt - self.target[1])) > self.tolerance_deg:
                self._last_change = now
            self.target = (pan, tilt)
        reported = self.pan_tilt.angles()
        on = (reported[0] is not None and reported[1] is not None
              and abs(reported[0] - pan) <= self.tolerance_deg
              and abs(reported[1] - tilt) <= self.tolerance_deg)
        if not on:
            self._on_target_since = None
            self.settled = False
            return
        if self._on_target_since is None:
            self._on_target_since = now
        self.settled = now - max(self._on_target_since, self._last_change) >= self.settle_s
