"""The perception's calls, for the mission's executive and `ramp sim perceive`.

Everything around the localizer and the obstacle detector (the rig, the AHRS, the gimbal, the
scan records, the 3D sweep, the mission's states) is written against this module alone, so
the pieces inside (`localizer.py`, `lines.py`, `relevel.py`, `cloud.py`, `obstacles.py`) can
change without touching their callers. Pure functions and one stateful tracker: no clock, no
I/O; the caller takes the scans (`scans.ScanCollector`) and runs the sweep (`sweep.Sweep`).

API (arena frame of SPEC 6.1, metres and radians, `confidence` in 0..1)::

    localize(records, *, hint=None, yaw_prior=None, prior_pose=None,
             yaw_sigma=YAW_SIGMA, prior_cov=None) -> Localization
        One localization from level scans taken while the robot stood still (the last
        record's view; the others taken from the same view are fused beam by beam, median).
        `hint`: the start box ("left"/"right") at initialisation; `yaw_prior`: the AHRS yaw,
        which breaks the arena's symmetry mid-run, one-sigma `yaw_sigma`; `prior_pose`: the
        (x, y, yaw) odometry predicts, with its 3x3 covariance `prior_cov` (a loose default
        when None). Never a confident wrong pose: `lost` with a reason instead.
    Tracker(*, odometry=None, yaw_sigma=YAW_SIGMA)   the pose between scans: odometry
                                          (`Perception.odometry`) predicts, the walls correct
        .initialise(records, *, hint=None, yaw_prior=None) -> Localization   global search
        .update(records, *, yaw_prior=<records' AHRS yaw>) -> Localization   tracked fix
        .relocalize(records, *, yaw_prior=<records' AHRS yaw>) -> Localization  after a loss
        .advance(t)                       the estimate moved to clock time t by the odometry
                                          (update/relocalize do it to their scans' time)
        .predict(dx, dy, dyaw)            or by hand: robot-frame motion since last time
        .pose (PoseEstimate | None, dead-reckoned while lost, confidence 0 then), .lost,
        .covariance, .last, .t (the moment .pose refers to)
    detect_obstacles(records, pose) -> list[Obstacle]
        Rocks and craters from the records of a 3D sweep taken standing at `pose` (any object
        with x, y, yaw). `detect(records, pose)` gives the whole `obstacles.Detection`.
    plan_scan(config, pose=None, *, ahead_m=None, pan_deg=0.0) -> SweepPlan | None
        The 3D sweep's tilts (`cloud.plan_sweep`), along the heading turned by `pan_deg`:
        ground lines every `sweep_spacing_m` from as far as the obstacle region ends
        (+0.3 m) when that direction faces it, else up to `sweep_far_m`, never beyond the
        wall there (from `pose`, or from `ahead_m` that `free_ahead` measured when lost);
        the steepest tilt 5 deg inside the servo's travel. None when there is no ground to
        scan. Run it with `sweep.Sweep(leveller, collector, pan_tilt, plan, ahrs=ahrs)`.
    level_from_floor(records) -> LevelHint | None
        Where level is, from the floor a sweep saw (a RANSAC plane over 1.5 m or more in
        every direction): what a shifted IMU mount hides from the walls. None when the
        records show too little floor (a wall close ahead: sweep panned to the sides too).
    free_ahead(records, bearing_deg=0.0) -> float   how far from the footprint centre, along
        a bearing of the chassis, a level scan meets something, m (inf when nothing)
    fuse_scans(records) -> (ScanRecord, n)   the records of the last one's view, one median
        range per beam (what `localize` and the tracker localize)
    HIGH_CONFIDENCE (0.5): every pose reported has at least this confidence;
    FLOOR_ADOPT_DEG (1.5): a floor this far from the AHRS' level means the IMU moved.

    Localization: pose (PoseEstimate | None; None exactly when lost), lost, candidates
        (PoseEstimate, best first: every pose the symmetric arena allows, as thesis figure
        5.39; their `confidence` is their probability), reason ("" unless lost), level
        (LevelHint | None: the re-leveller's chassis attitude when the scan showed a tilt),
        covariance (3x3 or None), wall_points, residual_rms (m), segments (level frame,
        for plots), scans (how many records were fused)
    PoseEstimate(x, y, yaw, confidence)   Obstacle: kind ("rock"|"crater"), x, y, d (+ height,
    LevelHint(roll, pitch, weight, t)       points, partial; `as_dict()` for JSON)

How the mission uses it (what `ramp sim perceive` does, `ramp/simulation/perceive.py`):

1. Level scans (`localize_scans` of them, the gimbal settled at 0) ->
   `tracker.initialise(records, hint=box)` at the start, `yaw_prior=ahrs.yaw` without a box;
   `relocalize(records)` after a loss; `update(records)` while tracking.
2. A `level` in the answer that disagrees with the AHRS (by its `hint_adopt_deg`):
   `ahrs.level_hint(level.roll, level.pitch, level.weight, t=level.t)` (the AHRS folds it
   into its mount correction, so the gimbal levels right again), wait for the gimbal to
   settle, back to 1 (bounded tries: `max_relocalize_tries`).
3. `plan_scan(config, pose)` (lost: `ahead_m=free_ahead(records)`) -> `sweep.Sweep`. If the
   AHRS corrected its mount since the level scans (`ahrs.correction` changed: it caught the
   IMU moving while parked), they are spoiled: back to 1.
4. `level_from_floor(sweep.records)`; None (a wall ahead): sweep with `pan_deg` 90 and -90
   too and try on all the records. Beyond `FLOOR_ADOPT_DEG` from the AHRS: as in 2.
5. Not lost: `ahrs.correct_yaw(pose.yaw, pose.confidence)`, `detect_obstacles(sweep.records,
   pose)`. Lost: stop, and after the tries wait for the operator (SPEC 6.3).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Protocol

import numpy as np

from ramp.autonomy import arena
from ramp.autonomy.mount import rotation_zyx
from ramp.autonomy.perception import localizer as loc
from ramp.autonomy.perception.cloud import SweepPlan, merge, plan_sweep
from ramp.autonomy.perception.coverage import GroundCoverage
from ramp.autonomy.perception.lines import Segment
from ramp.autonomy.perception.obstacles import Detection, Obstacle, fit_plane_ransac
from ramp.autonomy.perception.obstacles import detect_obstacles as detect_in_cloud
from ramp.autonomy.perception.records import FloatArray, ScanRecord
from ramp.errors import RampError

if TYPE_CHECKING:
    from ramp.autonomy.config import AutonomyConfig
    from ramp.autonomy.odometry import Odometry

__all__ = [
    "FLOOR_ADOPT_DEG", "HIGH_CONFIDENCE", "OBSTACLE_KINDS", "START_BOXES", "YAW_SIGMA",
    "LevelHint", "Localization", "Obstacle", "PerceptionUnavailable", "PoseEstimate",
    "Tracker", "detect", "detect_obstacles", "free_ahead", "fuse_scans", "level_from_floor",
    "localize", "plan_scan",
]

START_BOXES = arena.START_BOXES
OBSTACLE_KINDS = ("rock", "crater")
HIGH_CONFIDENCE = loc.HIGH_CONFIDENCE  # a reported pose has at least this confidence
YAW_SIGMA = loc.YAW_SIGMA

#: A loose odometry covariance for `localize(prior_pose=...)` without one: 0.3 m, 10 deg.
DEFAULT_PRIOR_COV = np.diag((0.3 ** 2, 0.3 ** 2, math.radians(10.0) ** 2))

#: Records fused into one scan must share the view: gimbal angles and attitude this close.
SAME_VIEW_DEG = 0.05
SAME_ATTITUDE_DEG = 0.2

#: The 3D sweep: ground lines this far apart, this far ahead at most when the robot does not
#: face the obstacle region, never closer than this to the wall ahead (its foot is no floor).
SWEEP_SPACING_M = 0.04
SWEEP_FAR_M = 3.85
WALL_CLEAR_M = 0.15
REGION_MARGIN_M = 0.3  # past the obstacle region's far edge (`cloud.region_distances`)
NEAR_M = 0.3  # asked for; the tilt limit decides (`SweepPlan.blind_m`)
#: The steepest tilt planned stays this far inside the servo's travel, so the gimbal can
#: still level it on a chassis pitched nose up as far as the raked arena allows.
TILT_MARGIN_DEG = 5.0

#: The floor: returns this far from the footprint centre at most, below this height in the
#: level frame (walls and whatever stands above a rock's height are not floor), at least this
#: many of them on the plane, spread at least this far in every direction (a strip of floor
#: in front of a wall says little about the pitch), the plane through the chassis' feet.
FLOOR_RADIUS_M = 3.5
FLOOR_MAX_Z_M = 0.45
FLOOR_MIN_POINTS = 2000
FLOOR_MIN_EXTENT_M = 1.5
FLOOR_MAX_OFFSET_M = 0.10
FLOOR_MAX_SLOPE = math.tan(math.radians(14.0))  # an IMU shift is 4-8 deg, plus a lean
#: A floor that disagrees with the AHRS' level by more than this means the IMU moved. The
#: raked floor's waves tilt the plane seen (1.5 m or more across) by up to 0.5 deg (measured
#: on the simulated arena, 40 poses), the AHRS errs by up to 0.4 deg with a drifting gyro;
#: a shifted mount is 4-8 deg off.
FLOOR_ADOPT_DEG = 1.5


class PerceptionUnavailable(RampError):
    """A perception stage this build does not have (callers written before the localizer
    and the detector were in the tree catch it; nothing raises it now)."""


@dataclass(frozen=True)
class PoseEstimate:
    """A robot pose in the arena (footprint centre, heading counter-clockwise from +x)."""

    x: float
    y: float
    yaw: float  # rad
    confidence: float = 1.0  # 0..1


@dataclass(frozen=True)
class LevelHint:
    """What the scan says about level: the chassis' roll and pitch (rad) at time `t` (the
    records' clock), with a confidence `weight` (0..1). Fed to `Ahrs.level_hint`, which
    corrects its idea of gravity and so the gimbal's set-point."""

    roll: float
    pitch: float
    weight: float
    t: float | None = None


@dataclass(frozen=True, eq=False)
class Localization:
    """One localization: the pose, or `lost` with the reason; every pose the scan allows."""

    pose: PoseEstimate | None  # None when lost
    lost: bool
    candidates: tuple[PoseEstimate, ...] = ()  # best first (thesis fig. 5.39); may be empty
    reason: str = ""  # why lost ("too few wall points", "large residuals (6.1 cm RMS)", ...)
    level: LevelHint | None = None  # the re-leveller's opinion, when it found a tilt
    covariance: FloatArray | None = None  # 3x3 (m^2, rad^2) of the pose
    wall_points: int = 0
    residual_rms: float = math.nan  # m
    segments: tuple[Segment, ...] = ()  # wall segments in the level frame (plots)
    scans: int = 0  # records fused into the scan localized


class HasPose(Protocol):
    @property
    def x(self) -> float: ...

    @property
    def y(self) -> float: ...

    @property
    def yaw(self) -> float: ...


# ---- localization ------------------------------------------------------------------------------


def fuse_scans(records: Sequence[ScanRecord]) -> tuple[ScanRecord, int]:
    """One scan from the records taken from the last one's view (same gimbal angles and
    attitude): the median range of each beam, NaN where fewer than half saw an echo (a dust
    echo is one scan's, a wall's top missed is every scan's). Returns it and how many fused."""
    if not records:
        raise ValueError("no scan to localize with")
    last = records[-1]
    same = [r for r in records if _same_view(r, last)]
    if len(same) == 1:
        return last, 1
    stack = np.stack([r.ranges for r in same])
    n = stack.shape[0]
    seen = np.isfinite(stack).sum(axis=0)
    ordered = np.sort(stack, axis=0)  # NaN last
    cols = np.arange(stack.shape[1])
    lo = np.clip((seen - 1) // 2, 0, n - 1)
    hi = np.clip(seen // 2, 0, n - 1)
    median = 0.5 * (ordered[lo, cols] + ordered[hi, cols])
    ranges = np.where(2 * seen >= n, median, np.nan)
    mid = same[len(same) // 2]
    fused = replace(mid, ranges=ranges, roll=float(np.mean([r.roll for r in same])),
                    pitch=float(np.mean([r.pitch for r in same])),
                    started=same[0].started)
    return fused, len(same)


def _same_view(a: ScanRecord, b: ScanRecord) -> bool:
    return (abs(a.tilt_deg - b.tilt_deg) <= SAME_VIEW_DEG
            and abs(a.pan_deg - b.pan_deg) <= SAME_VIEW_DEG
            and math.degrees(max(abs(a.roll - b.roll), abs(a.pitch - b.pitch)))
            <= SAME_ATTITUDE_DEG
            and np.array_equal(np.asarray(a.lidar_position), np.asarray(b.lidar_position))
            and a.ranges.shape == b.ranges.shape)


def _answer(res: loc.Localization, record: ScanRecord, fused: int) -> Localization:
    """The localizer's answer in this module's terms."""
    pose = None
    if not res.lost and res.pose is not None:
        pose = PoseEstimate(res.pose.x, res.pose.y, res.pose.yaw, res.confidence)
    kept = [c for c in res.candidates if c.note != "the robot would stand outside the arena"]
    kept.sort(key=lambda c: (-c.probability, -c.quality))
    candidates = tuple(PoseEstimate(c.pose.x, c.pose.y, c.pose.yaw, c.probability)
                       for c in kept[:4])
    level = None
    fix = res.relevel
    if fix is not None and fix.found:
        level = LevelHint(fix.roll, fix.pitch, 1.0, record.t)
    return Localization(pose, pose is None, candidates, res.reason if pose is None else "",
                        level, res.covariance, res.wall_points, res.residual_rms,
                        res.segments, fused)


def localize(records: Sequence[ScanRecord], *, hint: str | None = None,
             yaw_prior: float | None = None,
             prior_pose: tuple[float, float, float] | None = None,
             yaw_sigma: float = YAW_SIGMA, prior_cov: FloatArray | None = None,
             ) -> Localization:
    """The robot's pose from level 2D scans taken while it stood still (module docstring)."""
    if hint is not None and hint not in START_BOXES:
        raise ValueError(f"hint {hint!r} is not a start box ({', '.join(START_BOXES)})")
    record, fused = fuse_scans(records)
    prior = None
    if prior_pose is not None:
        cov = DEFAULT_PRIOR_COV if prior_cov is None else np.asarray(prior_cov, dtype=float)
        prior = loc.PosePrior(loc.Pose(*prior_pose), cov)
    res = loc.localize(record, hint=hint, yaw_prior=yaw_prior, yaw_sigma=yaw_sigma,
                       prior=prior)
    return _answer(res, record, fused)


class Tracker:
    """The pose between scans: odometry predicts, the walls correct (`localizer.Localizer`),
    every answer in this module's terms. Deterministic, no clock of its own: with an
    `odometry` (`ramp.autonomy.odometry.Odometry`, fed the drive commands), every fix first
    moves the estimate to the moment its scans were taken, and `advance(t)` to any moment."""

    def __init__(self, *, odometry: Odometry | None = None,
                 yaw_sigma: float = YAW_SIGMA) -> None:
        self._localizer = loc.Localizer(yaw_sigma=yaw_sigma)
        self.odometry = odometry
        self.t: float | None = None  # the moment the estimate refers to
        self.last: Localization | None = None

    @property
    def lost(self) -> bool:
        return self._localizer.lost

    @property
    def pose(self) -> PoseEstimate | None:
        """The estimate (dead-reckoned while lost, with confidence 0), None before a fix."""
        p = self._localizer.pose
        if p is None:
            return None
        conf = 0.0
        if not self.lost and self.last is not None and self.last.pose is not None:
            conf = self.last.pose.confidence
        return PoseEstimate(p.x, p.y, p.yaw, conf)

    @property
    def covariance(self) -> FloatArray | None:
        return self._localizer.covariance

    def initialise(self, records: Sequence[ScanRecord], *, hint: str | None = None,
                   yaw_prior: float | None = None) -> Localization:
        """Global localization with no pose prior (the start box as `hint`)."""
        record, fused = fuse_scans(records)
        res = self._localizer.initialise(record, hint=hint, yaw_prior=yaw_prior)
        return self._keep(res, record, fused)

    def predict(self, dx: float, dy: float, dyaw: float) -> None:
        """Move the estimate by a robot-frame motion (forward, left, turn) since last time
        (what `advance` does from the odometry; call one or the other)."""
        self._localizer.predict(dx, dy, dyaw)

    def advance(self, t: float) -> None:
        """Move the estimate to clock time `t` with what the odometry integrated."""
        if self.odometry is not None and self.t is not None and t != self.t:
            self.predict(*self.odometry.relative(self.t, t))
        self.t = t

    def update(self, records: Sequence[ScanRecord], *,
               yaw_prior: float | None = None) -> Localization:
        """Correct the estimate with scans (the yaw prior defaults to their AHRS yaw)."""
        record, fused = fuse_scans(records)
        self.advance(record.t)
        return self._keep(self._localizer.update(record, yaw_prior=yaw_prior), record, fused)

    def relocalize(self, records: Sequence[ScanRecord], *,
                   yaw_prior: float | None = None) -> Localization:
        """Search globally again, the pose prior forgotten (the recovery after a loss)."""
        record, fused = fuse_scans(records)
        self.advance(record.t)
        return self._keep(self._localizer.relocalize(record, yaw_prior=yaw_prior), record,
                          fused)

    def _keep(self, res: loc.Localization, record: ScanRecord, fused: int) -> Localization:
        self.last = _answer(res, record, fused)
        self.t = record.t
        return self.last


# ---- level from the floor ---------------------------------------------------------------------


def level_from_floor(records: Sequence[ScanRecord]) -> LevelHint | None:
    """The chassis' roll and pitch the floor says, from scans that see it (a 3D sweep).

    The floor's returns in the level frame of the records' own attitude lie on a plane that
    is level exactly when that attitude is right; its tilt is the AHRS' error. The robot's
    own frame, the walls (vertical: no RANSAC plane through them is shallow enough) and rocks
    (too few) do not move it. None when the floor seen is too small to tell."""
    if not records:
        return None
    pts = np.concatenate([r.points_level() for r in records])
    hx = arena.ROBOT_LENGTH_M / 2.0 + 0.05
    hy = arena.ROBOT_WIDTH_M / 2.0 + 0.05
    dist = np.hypot(pts[:, 0], pts[:, 1])
    keep = (~((np.abs(pts[:, 0]) < hx) & (np.abs(pts[:, 1]) < hy)) & (dist < FLOOR_RADIUS_M)
            & (pts[:, 2] < FLOOR_MAX_Z_M))
    pts = pts[keep]
    if pts.shape[0] < FLOOR_MIN_POINTS:
        return None
    a, b, c = fit_plane_ransac(pts, band=0.03, iterations=200, sample=4000, seed=0,
                               max_slope=FLOOR_MAX_SLOPE)
    on = np.abs(pts[:, 2] - (a * pts[:, 0] + b * pts[:, 1] + c)) < 0.03
    floor = pts[on]
    if floor.shape[0] < FLOOR_MIN_POINTS or abs(c) > FLOOR_MAX_OFFSET_M:
        return None
    spread = floor[:, :2] - floor[:, :2].mean(axis=0)
    narrowest = float(np.linalg.eigvalsh(np.cov(spread.T)).min())
    if 2.0 * math.sqrt(3.0 * max(narrowest, 0.0)) < FLOOR_MIN_EXTENT_M:  # +-sqrt(3) sd
        return None
    mid = records[len(records) // 2]
    up_level = np.array((-a, -b, 1.0)) / math.sqrt(a * a + b * b + 1.0)
    believed = np.asarray(rotation_zyx(mid.roll, mid.pitch, 0.0))
    up = believed.T @ up_level  # true up in the chassis frame
    roll = math.atan2(float(up[1]), float(up[2]))
    pitch = -math.asin(max(-1.0, min(1.0, float(up[0]))))
    return LevelHint(roll, pitch, 1.0, mid.t)


def free_ahead(records: Sequence[ScanRecord], bearing_deg: float = 0.0,
               half_width_deg: float = 2.0) -> float:
    """How far from the footprint centre, along `bearing_deg` (chassis frame, counter-
    clockwise from ahead), the scans meet something: the median over the beams within
    `half_width_deg` of that bearing as seen from the scanner; inf if nothing answered."""
    record, _ = fuse_scans(records)
    rot = np.asarray(record.lidar_rotation)
    b = math.radians(bearing_deg)
    bearing = math.remainder(b - math.atan2(rot[1, 0], rot[0, 0]), 2 * math.pi)
    near = np.abs(np.remainder(record.angles - bearing + math.pi, 2 * math.pi) - math.pi)
    use = (near <= math.radians(half_width_deg)) & record.valid
    if not use.any():
        return math.inf
    r, a = record.ranges[use], record.angles[use]
    pts = np.column_stack((r * np.cos(a), r * np.sin(a), np.zeros_like(r)))
    chassis = pts @ rot.T + np.asarray(record.lidar_position)
    return float(np.median(chassis[:, 0] * math.cos(b) + chassis[:, 1] * math.sin(b)))


# ---- the 3D scan --------------------------------------------------------------------------------


def _wall_ahead(x: float, y: float, yaw: float) -> float:
    """Distance from (x, y) along `yaw` to the arena's boundary."""
    c, s = math.cos(yaw), math.sin(yaw)
    out = math.inf
    for d, lo, hi in ((c, x, arena.ARENA_LENGTH_M), (s, y, arena.ARENA_WIDTH_M)):
        if d > 1e-9:
            out = min(out, (hi - lo) / d)
        elif d < -1e-9:
            out = min(out, -lo / d)
    return max(out, 0.0)


def plan_scan(config: AutonomyConfig, pose: HasPose | None = None, *,
              ahead_m: float | None = None, pan_deg: float = 0.0) -> SweepPlan | None:
    """The 3D sweep for a robot standing at `pose` (or, lost, with `ahead_m` of free ground
    from its footprint centre along the pan), the gimbal panned `pan_deg` (0: straight
    ahead): see the module docstring."""
    mission = config.mission
    spacing = float(mission.get("sweep_spacing_m", SWEEP_SPACING_M))
    far = float(mission.get("sweep_far_m", SWEEP_FAR_M))
    if pose is not None:
        heading = pose.yaw + math.radians(pan_deg)
        c = math.cos(heading)
        if c > math.cos(math.radians(45.0)) and pose.x < arena.OBSTACLE_END_X_M:
            far = (arena.OBSTACLE_END_X_M + REGION_MARGIN_M - pose.x) / c
        far = min(far, _wall_ahead(pose.x, pose.y, heading) - WALL_CLEAR_M)
    if ahead_m is not None:
        far = min(far, ahead_m - WALL_CLEAR_M)
    tilt = config.gimbal.tilt
    try:
        return plan_sweep(config.lidar.mount, config.gimbal.pivot, near_m=NEAR_M, far_m=far,
                          spacing_m=spacing, tilt_min_deg=tilt.min_deg,
                          tilt_max_deg=tilt.max_deg - TILT_MARGIN_DEG,
                          velocity_dps=tilt.velocity_dps,
                          acceleration_dps2=tilt.acceleration_dps2, pan_deg=pan_deg)
    except ValueError:  # no ground ahead between the blind distance and the wall
        return None


def detect(records: Sequence[ScanRecord], pose: HasPose) -> Detection:
    """`obstacles.detect_obstacles` on the sweep's records merged at `pose`."""
    return detect_in_cloud(merge(records, pose.x, pose.y, pose.yaw))


def ground_coverage(records: Sequence[ScanRecord], pose: HasPose,
                    coverage: GroundCoverage | None = None) -> GroundCoverage:
    """`coverage` (none yet: empty) with the returns of a sweep taken at `pose` counted in:
    how densely the scans have sampled the obstacle region's floor (`perception.coverage`)."""
    base = coverage if coverage is not None else GroundCoverage.empty()
    if not records:
        return base
    return base.add(merge(records, pose.x, pose.y, pose.yaw).points)


def detect_obstacles(records: Sequence[ScanRecord], pose: HasPose) -> list[Obstacle]:
    """Rocks and craters (arena frame) from the 3D sweep's records taken at `pose`."""
    if not records:
        return []
    return list(detect(records, pose).obstacles)
