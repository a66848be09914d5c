"""Where a sensor sits on the chassis, and the pose of the LIDAR on its pan/tilt gimbal.

Frames (SPEC 6.1): the chassis frame has x forward, y left, z up, origin at the centre of the
footprint on the ground plane. A `Mount` is a sensor frame's pose in the chassis frame:
position in metres and orientation as ZYX Euler angles in degrees (yaw about z, then pitch
about the new y, then roll about the new x), so `rotation()` maps vectors from the sensor's
own axes into the chassis frame. Positive pitch turns +x toward -z (nose down), as in the
arena frame.

The gimbal (thesis fig. 5.28, an SPT200 pan/tilt): pan turns about the chassis z axis through
the `pivot`, positive counter-clockwise (to the left); tilt then turns about the panned y axis,
positive nose down (right-hand rule about +y, the same sign as pitch). The LIDAR's `Mount`
is its optical centre with pan = tilt = 0.

Plain Python 3x3 tuples keep this import-light; these are small, per-call matrices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]

IDENTITY: Mat3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@dataclass(frozen=True)
class Mount:
    """A sensor's pose on the chassis: metres and degrees, chassis frame, ZYX Euler."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0

    @property
    def position(self) -> Vec3:
        return (self.x, self.y, self.z)

    def rotation(self) -> Mat3:
        """Sensor axes -> chassis axes."""
        return rotation_zyx(math.radians(self.roll), math.radians(self.pitch),
                            math.radians(self.yaw))


def rotation_zyx(roll: float, pitch: float, yaw: float) -> Mat3:
    """Rz(yaw) @ Ry(pitch) @ Rx(roll), angles in radians."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return (
        (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        (-sp, cp * sr, cp * cr),
    )


def euler_zyx(r: Mat3) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in radians of a rotation matrix (inverse of `rotation_zyx`)."""
    pitch = math.asin(max(-1.0, min(1.0, -r[2][0])))
    roll = math.atan2(r[2][1], r[2][2])
    yaw = math.atan2(r[1][0], r[0][0])
    return roll, pitch, yaw


def axis_angle(axis: Vec3, angle: float) -> Mat3:
    """Rotation by `angle` (rad) about the unit vector `axis` (Rodrigues)."""
    x, y, z = axis
    n = math.sqrt(x * x + y * y + z * z)
    if n == 0.0:
        raise ValueError("a rotation axis cannot be the zero vector")
    x, y, z = x / n, y / n, z / n
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return (
        (t * x * x + c, t * x * y - s * z, t * x * z + s * y),
        (t * x * y + s * z, t * y * y + c, t * y * z - s * x),
        (t * x * z - s * y, t * y * z + s * x, t * z * z + c),
    )


def mat_mul(a: Mat3, b: Mat3) -> Mat3:
    """Written out (it runs several times a tick); `0.0 +` first keeps the exact sums (and
    the sign of a zero) that `sum()` gave on the Python this project runs."""
    (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = b
    return tuple(  # type: ignore[return-value]
        (0.0 + r0 * b00 + r1 * b10 + r2 * b20,
         0.0 + r0 * b01 + r1 * b11 + r2 * b21,
         0.0 + r0 * b02 + r1 * b12 + r2 * b22)
        for r0, r1, r2 in a
    )


def mat_vec(a: Mat3, v: Vec3) -> Vec3:
    return (
        a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
        a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
        a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2],
    )


def transpose(a: Mat3) -> Mat3:
    return tuple(zip(*a, strict=True))  # type: ignore[return-value]


def angle_between(u: Vec3, v: Vec3) -> float:
    """The angle in radians between two non-zero vectors."""
    (u0, u1, u2), (v0, v1, v2) = u, v  # written out as mat_mul, the same sums
    dot = 0.0 + u0 * v0 + u1 * v1 + u2 * v2
    nu = math.sqrt(0.0 + u0 * u0 + u1 * u1 + u2 * u2)
    nv = math.sqrt(0.0 + v0 * v0 + v1 * v1 + v2 * v2)
    return math.acos(max(-1.0, min(1.0, dot / (nu * nv))))


def gimbal_rotation(pan_deg: float, tilt_deg: float) -> Mat3:
    """The gimbal's own turn: pan about z, then tilt about the panned y."""
    return rotation_zyx(0.0, math.radians(tilt_deg), math.radians(pan_deg))


def lidar_pose(lidar: Mount, pivot: Vec3, pan_deg: float, tilt_deg: float) -> tuple[Vec3, Mat3]:
    """The LIDAR's optical centre and axes in the chassis frame for a pan and a tilt.

    `lidar` is its mount with the gimbal at zero; `pivot` is where the pan and tilt axes
    cross. Returns (position in metres, rotation LIDAR axes -> chassis axes).
    """
    g = gimbal_rotation(pan_deg, tilt_deg)
    rel = (lidar.x - pivot[0], lidar.y - pivot[1], lidar.z - pivot[2])
    turned = mat_vec(g, rel)
    position = (pivot[0] + turned[0], pivot[1] + turned[1], pivot[2] + turned[2])
    return position, mat_mul(g, lidar.rotation())
