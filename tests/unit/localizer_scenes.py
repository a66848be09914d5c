"""Scans of the simulated arena as the autonomy would record them, for the localizer tests.

The simulator (`firmware_like`) casts the beams from the TRUE pose and attitude; the record
carries what the autonomy BELIEVES: the AHRS roll and pitch (true plus an error, to play a
drifting AHRS or a shifted IMU mount) and the gimbal angles it commanded to level the LIDAR
against that belief. The LIDAR sits where the simulator puts it (`LidarParams.mount_*`), and
the simulator's gimbal turns about the optical centre, so the pivot is the mount itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware_like.arena_params import LidarParams
from firmware_like.lidar_view import LidarView, Scan
from firmware_like.marte import MarteWorld
from ramp.autonomy.mount import Mount, lidar_pose
from ramp.autonomy.perception.localizer import Pose
from ramp.autonomy.perception.records import ScanRecord

_LP = LidarParams()
LIDAR_MOUNT = Mount(x=_LP.mount_x, y=_LP.mount_y, z=_LP.mount_z)


@dataclass
class Shot:
    """One scan: the record the autonomy gets and the simulator's truth about it."""

    record: ScanRecord
    scan: Scan
    truth: Pose


def shoot(world: MarteWorld, view: LidarView, *, roll_error: float = 0.0,
          pitch_error: float = 0.0, pan: float = 0.0, tilt: float | None = None,
          yaw: float | None = None, noise: bool = True, digging: bool = False,
          t: float = 0.0) -> Shot:
    """Scan from the world's pose. The AHRS believes roll/pitch = truth + error (rad); the
    gimbal levels against that belief (tilt = -believed pitch) unless `tilt` is given."""
    c = world.chassis_pose()
    roll_b, pitch_b = c.roll + roll_error, c.pitch + pitch_error
    gimbal_tilt = -pitch_b if tilt is None else tilt
    scan = view.scan(view.pose(c.x, c.y, c.z, c.roll, c.pitch, c.yaw, pan, gimbal_tilt),
                     noise=noise, digging=digging)
    pos, rot = lidar_pose(LIDAR_MOUNT, LIDAR_MOUNT.position, math.degrees(pan),
                          math.degrees(gimbal_tilt))
    record = ScanRecord(t=t, ranges=scan.ranges.copy(), angles=view.angles.copy(),
                        lidar_position=pos, lidar_rotation=rot, roll=roll_b, pitch=pitch_b,
                        yaw=yaw, pan_deg=math.degrees(pan), tilt_deg=math.degrees(gimbal_tilt))
    return Shot(record, scan, Pose(c.x, c.y, c.yaw))


def errors(pose: Pose, truth: Pose) -> tuple[float, float]:
    """(position error m, heading error deg)."""
    return (math.hypot(pose.x - truth.x, pose.y - truth.y),
            abs(math.degrees(math.remainder(pose.yaw - truth.yaw, 2.0 * math.pi))))


def masked(record: ScanRecord, keep: np.ndarray) -> ScanRecord:
    """The record with every beam outside `keep` (bool per beam) turned into no-echo."""
    ranges = np.where(keep, record.ranges, np.nan)
    return ScanRecord(record.t, ranges, record.angles, record.lidar_position,
                      record.lidar_rotation, record.roll, record.pitch, record.yaw,
                      record.pan_deg, record.tilt_deg)
