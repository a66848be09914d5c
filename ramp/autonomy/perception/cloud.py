"""The 3D scan: a tilt sweep of the gimbal, and its 2D scans merged into one point cloud.

The thesis' 3D scanner (5.3.4) "repeatedly increases the pitch on the gimbal and takes a 2D
scan at each pre-defined angle". Here the pre-defined angles are planned, not guessed: a
scan tilted nose-down by tau meets level ground along a line h / tan(tau) ahead of the
LIDAR (h its height), perpendicular to the heading and across the whole 270 deg fan. The
plan spaces those ground lines evenly, `spacing_m` apart, between a near and a far distance
ahead of the robot, so that an obstacle gets the same number of lines across it wherever it
stands. Far lines need fine tilt steps (at 3 m ahead, 0.1 deg moves the line by 2.4 cm);
near ones coarse steps.

Stop-and-go, as the thesis did it: the gimbal moves to a tilt (a trapezoid at the servo's
velocity limit and acceleration), the scan under way when it arrives is dropped (its beams
straddle two tilts), the next full scan is kept. So each tilt costs its move plus up to two
scan periods (25 ms each), and `SweepPlan.duration_s` is that worst case, back to level at
the end.

    plan = plan_sweep(mount, pivot, near_m=0.55, far_m=3.6, tilt_max_deg=45, ...)
    for tilt in plan.tilts_deg: ... move, wait, take a ScanRecord ...
    cloud = merge(records, x, y, yaw)        # the localizer's pose of the robot

`merge` puts every valid return in the arena frame (SPEC 6.1) with each record's own roll
and pitch (the AHRS' at that scan) and remembers where each point came from (which scan,
which beam, the LIDAR's centre), which the obstacle detector needs to reason about what a
beam passed over (`ramp.autonomy.perception.obstacles`).

A moving robot is not supported: the sweep is taken standing still, and one pose is given
for all of it (the mission stops to scan).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ramp.autonomy.mount import Mount, Vec3, lidar_pose, rotation_zyx
from ramp.autonomy.perception.records import FloatArray, ScanRecord

IntArray = npt.NDArray[np.intp]

SCAN_PERIOD_S = 0.025  # UTM-30LX-EW: 40 scans a second (SPEC 6.2)


@dataclass(frozen=True)
class SweepPlan:
    """The tilts of one 3D scan, in the order to visit them, and what the sweep costs.

    `near_m`..`far_m` is the stretch of level ground ahead of the robot's footprint centre
    (chassis x) that the ground lines cover, `spacing_m` apart; `near_m` may be farther than
    asked when the tilt limit does not let the LIDAR look steeper (`blind_m` says how far
    ahead the ground stays unseen). `duration_s` is the worst case from `start_deg` through
    every tilt back to `end_deg`."""

    tilts_deg: tuple[float, ...]
    pan_deg: float
    near_m: float
    far_m: float
    spacing_m: float
    blind_m: float
    start_deg: float
    end_deg: float
    scan_period_s: float
    move_s: float  # moving between tilts, in all
    scanning_s: float  # waiting for the scans, in all
    duration_s: float

    @property
    def scans(self) -> int:
        return len(self.tilts_deg)


def move_time(delta_deg: float, velocity_dps: float, acceleration_dps2: float) -> float:
    """Seconds for a servo to move `delta_deg` from rest to rest: accelerate, cruise at the
    velocity limit, brake (a triangle when the move is too short to reach the limit)."""
    d = abs(delta_deg)
    if d == 0.0:
        return 0.0
    if d <= velocity_dps * velocity_dps / acceleration_dps2:
        return 2.0 * math.sqrt(d / acceleration_dps2)
    return d / velocity_dps + velocity_dps / acceleration_dps2


def ground_ahead(mount: Mount, pivot: Vec3, tilt_deg: float, pan_deg: float = 0.0) -> float:
    """Where the beam straight ahead of the LIDAR meets level ground (z = 0 of the chassis),
    as a distance ahead of the footprint centre along the pan direction; inf when the beam
    does not go down."""
    pos, rot = lidar_pose(mount, pivot, pan_deg, tilt_deg)
    ahead = rot[0][0], rot[1][0], rot[2][0]  # the LIDAR's x axis in the chassis frame
    if ahead[2] >= -1e-9:
        return math.inf
    t = pos[2] / -ahead[2]
    c, s = math.cos(math.radians(pan_deg)), math.sin(math.radians(pan_deg))
    return (pos[0] + t * ahead[0]) * c + (pos[1] + t * ahead[1]) * s


def tilt_for(mount: Mount, pivot: Vec3, distance_m: float, pan_deg: float = 0.0) -> float:
    """The tilt (deg) whose straight-ahead beam meets level ground `distance_m` ahead of the
    footprint centre (the inverse of `ground_ahead`, by bisection: the optical centre moves
    with the tilt when it is not on the tilt axis)."""
    lo, hi = 0.01, 89.9  # ground_ahead falls as the tilt grows
    if ground_ahead(mount, pivot, hi, pan_deg) >= distance_m:
        return hi
    if ground_ahead(mount, pivot, lo, pan_deg) <= distance_m:
        return lo
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if ground_ahead(mount, pivot, mid, pan_deg) > distance_m:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def plan_sweep(mount: Mount, pivot: Vec3, *, near_m: float, far_m: float,
               spacing_m: float = 0.04, tilt_min_deg: float = -30.0,
               tilt_max_deg: float = 45.0, velocity_dps: float = 60.0,
               acceleration_dps2: float = 360.0, pan_deg: float = 0.0,
               start_deg: float = 0.0, end_deg: float = 0.0,
               scan_period_s: float = SCAN_PERIOD_S) -> SweepPlan:
    """Tilts that lay ground lines every `spacing_m` from `far_m` to `near_m` ahead of the
    footprint centre (metres, chassis x along the pan direction), far first, within the
    tilt servo's limits; `mount` and `pivot` as in `ramp.autonomy.mount.lidar_pose`, the
    servo's speed as in `autonomy.yaml` (`gimbal.tilt`)."""
    for name, value in (("near_m", near_m), ("far_m", far_m), ("spacing_m", spacing_m),
                        ("velocity_dps", velocity_dps),
                        ("acceleration_dps2", acceleration_dps2)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")
    if not near_m < far_m:
        raise ValueError(f"near_m {near_m} must be less than far_m {far_m}")
    if not tilt_min_deg < tilt_max_deg:
        raise ValueError(f"tilt limits {tilt_min_deg}..{tilt_max_deg} are empty")
    blind = ground_ahead(mount, pivot, min(tilt_max_deg, 89.9), pan_deg)
    near = max(near_m, blind)
    if near >= far_m:
        raise ValueError(f"the tilt limit {tilt_max_deg:g} deg lets the LIDAR see level ground "
                         f"from {blind:.2f} m ahead only, beyond far_m {far_m}")
    n = max(2, math.ceil((far_m - near) / spacing_m - 1e-9) + 1)
    distances = np.linspace(far_m, near, n)
    tilts = [min(tilt_max_deg, max(tilt_min_deg, tilt_for(mount, pivot, float(d), pan_deg)))
             for d in distances]
    tilts = [round(t, 3) for t in tilts]
    path = [start_deg, *tilts, end_deg]
    moving = sum(move_time(b - a, velocity_dps, acceleration_dps2)
                 for a, b in zip(path, path[1:], strict=False))
    scanning = 2.0 * scan_period_s * len(tilts)  # the partial scan dropped, the full one kept
    return SweepPlan(tilts_deg=tuple(tilts), pan_deg=pan_deg, near_m=near, far_m=far_m,
                     spacing_m=(far_m - near) / (n - 1), blind_m=blind, start_deg=start_deg,
                     end_deg=end_deg, scan_period_s=scan_period_s, move_s=moving,
                     scanning_s=scanning, duration_s=moving + scanning)


@dataclass(frozen=True, eq=False)
class Cloud:
    """The returns of one 3D scan in the arena frame, each remembering where it came from.

    `points` (n, 3) arena x, y, z; `scan` (n,) which record (index into the sequence given
    to `merge`); `beam` (n,) which step of that record; `origins` (m, 3) each record's LIDAR
    optical centre in the arena; `tilts_deg` (m,) each record's tilt; `pose` the robot's
    (x, y, yaw) the cloud was placed with, `ground_z` the height given for its footprint."""

    points: FloatArray
    scan: IntArray
    beam: IntArray
    origins: FloatArray
    tilts_deg: FloatArray
    pose: tuple[float, float, float]
    ground_z: float = 0.0

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def ranges(self) -> FloatArray:
        """(n,) distance of each point from its scan's optical centre."""
        out: FloatArray = np.linalg.norm(self.points - self.origins[self.scan], axis=1)
        return out

    def directions(self) -> FloatArray:
        """(n, 3) unit direction of each point's beam, arena frame."""
        d = self.points - self.origins[self.scan]
        out: FloatArray = d / np.linalg.norm(d, axis=1)[:, None]
        return out


def lidar_origin(record: ScanRecord, x: float, y: float, yaw: float,
                 ground_z: float = 0.0) -> FloatArray:
    """The record's LIDAR optical centre in the arena frame (as `ScanRecord.points_arena`
    moves its points)."""
    rot = np.asarray(rotation_zyx(record.roll, record.pitch, yaw), dtype=np.float64)
    out: FloatArray = rot @ np.asarray(record.lidar_position, dtype=np.float64) + np.array(
        (x, y, ground_z))
    return out


def merge(records: Sequence[ScanRecord], x: float, y: float, yaw: float,
          ground_z: float = 0.0) -> Cloud:
    """One point cloud in the arena frame from the records of a sweep taken with the robot
    standing at (x, y, yaw) (m, m, rad), each record placed with its own roll and pitch."""
    pts: list[FloatArray] = []
    scans: list[IntArray] = []
    beams: list[IntArray] = []
    origins = np.zeros((len(records), 3))
    tilts = np.zeros(len(records))
    for i, rec in enumerate(records):
        p = rec.points_arena(x, y, yaw, ground_z)
        pts.append(p)
        beams.append(np.nonzero(rec.valid)[0])
        scans.append(np.full(p.shape[0], i, dtype=np.intp))
        origins[i] = lidar_origin(rec, x, y, yaw, ground_z)
        tilts[i] = rec.tilt_deg
    if not pts:
        return Cloud(np.zeros((0, 3)), np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp),
                     origins, tilts, (x, y, yaw), ground_z)
    return Cloud(np.concatenate(pts), np.concatenate(scans), np.concatenate(beams), origins,
                 tilts, (x, y, yaw), ground_z)
