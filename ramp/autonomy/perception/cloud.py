"""The 3D scan: a tilt sweep of the gimbal, and its 2D scans merged into one point cloud.

The thesis' 3D scanner (5.3.4) "repeatedly increases the pitch on the gimbal and takes a 2D
scan at each pre-defined angle". Here the angles are planned: a scan tilted nose-down by tau
meets level ground along a line h / tan(tau) ahead of the LIDAR (h its height), across the
whole 270 deg fan and perpendicular to the pan direction. `plan_sweep` spaces those lines
evenly, `spacing_m` apart, from `far_m` to `near_m` ahead of the footprint centre, so an
obstacle gets the same number of lines across it wherever it stands. Far lines need fine
steps (3 m ahead of a scanner 0.7 m up, 0.1 deg moves the line by 2.4 cm), near ones coarse.

    plan = sweep_from_config(config, *region_distances(robot_x))   # robot facing +x
    plan.tilts_deg, plan.duration_s, plan.blind_m
    ... for each tilt: move, wait for the servo, drop the scan under way, keep the next ...
    cloud = merge(records, x, y, yaw)       # the localizer's pose of the robot, standing

**Tilts are relative to the horizon.** The gimbal levels them against the AHRS pitch (servo
tilt = plan tilt - chassis pitch when panned straight ahead), so the lines land where planned
on a pitched chassis too. The records carry the servo's own tilt and the AHRS attitude, and
`merge` uses those, so a levelling error only moves lines, it does not bend the cloud. Roll
cannot be levelled with a pan/tilt head: it tips the lines sideways (1 deg is 3 cm at 1.9 m to
the side), which is why `region_distances` reaches 0.3 m past the region by default. A rock
is seen to its top only by lines that reach past it by height x distance / h (0.6 m for a
15 cm rock 3 m out): the far rows of the region are measured from their lower part.

**Stop-and-go**, as the thesis did it: the gimbal moves to a tilt (a trapezoid at the servo's
velocity limit and acceleration), the scan under way when it arrives is dropped (its beams
straddle two tilts), the next full scan is kept: each tilt costs its move plus up to two scan
periods (25 ms each). `SweepPlan.duration_s` is that worst case, back to `end_deg` after.
With autonomy.yaml's tilt servo (60 deg/s, 360 deg/s^2) the start-region sweep below is 82
scans and 12.6 s; the moves dominate (small steps are acceleration-bound).

**The tilt limit blinds the scanner close ahead**: level ground nearer than
`ground_ahead(mount, pivot, tilt_max)` is never seen (`SweepPlan.blind_m`). With the
simulator's scanner (0.40 m ahead, 0.70 m up) a 45 deg travel would leave 1.10 m ahead of the
footprint centre unseen: from the start region (x <= 0.9 facing +x) the first 0.2 m of the
obstacle region. 75 deg brings it down to 0.59 m, inside the start region: autonomy.yaml's
tilt servo reaches 80 deg and `pipeline.plan_scan` plans to 75 (5 deg kept for the pitch).

`merge` puts every valid return in the arena frame (SPEC 6.1) with each record's own roll and
pitch and remembers where each point came from (which scan, which beam, the scanner's
centre), which the obstacle detector needs to reason about what a beam passed over
(`ramp.autonomy.perception.obstacles`). One pose for the whole sweep: the robot stands still.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ramp.autonomy import arena
from ramp.autonomy.mount import Mount, Vec3, lidar_pose, rotation_zyx
from ramp.autonomy.perception.records import FloatArray, ScanRecord

if TYPE_CHECKING:
    from ramp.autonomy.config import AutonomyConfig

IntArray = npt.NDArray[np.intp]

SCAN_PERIOD_S = 0.025  # UTM-30LX-EW: 40 scans a second (SPEC 6.2)


@dataclass(frozen=True)
class SweepPlan:
    """The tilts of one 3D scan (degrees nose down from the horizon, at `pan_deg`), in the
    order to visit them, and what the sweep costs.

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


def region_distances(robot_x: float, x_from: float = arena.START_END_X_M,
                     x_to: float = arena.OBSTACLE_END_X_M,
                     far_margin_m: float = 0.3) -> tuple[float, float]:
    """(near_m, far_m) for `plan_sweep` that cover the arena from `x_from` to `x_to` (SPEC
    6.1's obstacle region by default) and `far_margin_m` beyond, for a robot at `robot_x`
    facing +x (its heading within a few degrees). A `near_m` under the blind distance is
    fine: the plan starts where the tilt limit lets it."""
    near = max(x_from - robot_x, 0.05)
    far = x_to + far_margin_m - robot_x
    if far <= near:
        raise ValueError(f"nothing to scan ahead of x = {robot_x} between {x_from} and {x_to}")
    return near, far


def sweep_from_config(config: AutonomyConfig, near_m: float, far_m: float,
                      spacing_m: float = 0.04, pan_deg: float = 0.0) -> SweepPlan:
    """`plan_sweep` with the LIDAR mount, the gimbal's pivot and its tilt servo (limits,
    velocity, acceleration) of an `autonomy.yaml`."""
    tilt = config.gimbal.tilt
    return plan_sweep(config.lidar.mount, config.gimbal.pivot, near_m=near_m, far_m=far_m,
                      spacing_m=spacing_m, tilt_min_deg=tilt.min_deg, tilt_max_deg=tilt.max_deg,
                      velocity_dps=tilt.velocity_dps, acceleration_dps2=tilt.acceleration_dps2,
                      pan_deg=pan_deg)


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
