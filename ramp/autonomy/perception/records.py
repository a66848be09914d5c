"""A 2D scan together with where the LIDAR pointed when it was taken.

Every consumer of scans (the localizer, the re-leveller, the 3D scanner, the plots) needs the
same three things beside the ranges: the LIDAR's pose on the chassis (mount, pan, tilt), the
chassis attitude the AHRS believed in at that moment, and later the robot's pose in the arena.
Keeping them in one record, and the frame changes in one place, keeps every stage honest
about which estimate it used.

Frames (SPEC 6.1): LIDAR (x ahead, y left, z up through its spinning head) → chassis (x
forward, y left, z up, origin at the footprint's centre on the ground) → level (the chassis
frame turned by roll and pitch so z is true up, yaw left out) → arena (level frame turned by
yaw and moved to the robot's x, y).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ramp.autonomy.mount import Mat3, Vec3, rotation_zyx

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ScanRecord:
    """One scan and the estimates it was taken under."""

    t: float  # host clock (the injected one) when the beam ahead was measured, s
    ranges: FloatArray  # (n,) metres, NaN where the sensor saw nothing usable
    angles: FloatArray  # (n,) radians, counter-clockwise from the LIDAR's forward axis
    lidar_position: Vec3  # LIDAR optical centre in the chassis frame, m
    lidar_rotation: Mat3  # LIDAR axes -> chassis axes (ramp.autonomy.mount.lidar_pose)
    roll: float  # chassis roll the AHRS estimated at `t`, rad (left side up positive)
    pitch: float  # chassis pitch the AHRS estimated at `t`, rad (nose down positive)
    yaw: float | None = None  # AHRS yaw at `t`, rad CCW from +x, when it has one
    pan_deg: float = 0.0  # gimbal angles as the servos reported them (for plots and logs)
    tilt_deg: float = 0.0
    started: float | None = None  # host clock when its first beam was measured, s (a
    # stop-and-go sweep keeps only scans begun after the gimbal arrived)

    @property
    def valid(self) -> npt.NDArray[np.bool_]:
        return np.isfinite(self.ranges)

    def points_lidar(self) -> FloatArray:
        """(m, 3) valid returns in the LIDAR's own frame."""
        ok = self.valid
        r, a = self.ranges[ok], self.angles[ok]
        return np.column_stack((r * np.cos(a), r * np.sin(a), np.zeros_like(r)))

    def points_chassis(self) -> FloatArray:
        """(m, 3) valid returns in the chassis frame."""
        rot = np.asarray(self.lidar_rotation, dtype=np.float64)
        return self.points_lidar() @ rot.T + np.asarray(self.lidar_position)

    def points_level(self) -> FloatArray:
        """(m, 3) valid returns in the level frame: chassis origin, z true up, no yaw."""
        tilt = np.asarray(rotation_zyx(self.roll, self.pitch, 0.0), dtype=np.float64)
        return self.points_chassis() @ tilt.T

    def points_arena(self, x: float, y: float, yaw: float, ground_z: float = 0.0) -> FloatArray:
        """(m, 3) valid returns in the arena frame, for a robot at (x, y, yaw) whose
        footprint centre stands at height `ground_z`."""
        c, s = math.cos(yaw), math.sin(yaw)
        turn = np.array(((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0)))
        return self.points_level() @ turn.T + np.array((x, y, ground_z))
