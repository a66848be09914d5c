"""Where the robot is, from the arena's four walls — and when it cannot tell.

Thesis 5.3.4: straight lines extracted from a level 2D scan are matched to the walls; a
rectangle looks the same from a pose and from that pose turned 180 degrees about the arena's
centre, so the scan alone gives two (and, when only a corner is in view, up to four)
candidate poses; the start box breaks the symmetry at initialisation, the AHRS yaw later.
MARTE lost two autonomous runs to a tilted LIDAR that saw too little wall; so here a pose is
given only when the scan, the map and the priors agree, and otherwise the result says
`lost` and why.

One localization (`localize`, pure):

1. **Wall points.** The record's returns in the level frame, without the robot's own frame
   (anything inside the footprint, e.g. the BLE's posts at ~0.4 m) and without returns too
   low to be a wall (ground and rocks of a tilted scan: z below `min_wall_z`).
2. **Segments** (`lines.extract_lines`) give the yaw modulo 90 degrees (their dominant
   direction) and, for each of the four yaws, which wall each segment is; each wall seen
   fixes x or y. Every combination is a candidate; a prior pose is one more.
3. **Refinement**: point-to-line Gauss-Newton (ICP) of all wall points against the four
   walls, with a shrinking gate and Huber weights; its information matrix gives the
   covariance and which directions the scan cannot see (one wall: along it).
4. **Scoring**: the share of points within `inlier_gate` of a wall minus a penalty for points
   seen *through* a wall (impossible from a true pose; this rejects most 90-degree aliases);
   the 180-degree alias always scores the same and is left to the priors: the start box
   (`hint`, "left"/"right": the pose must lie in that box of the start region), the yaw
   prior (`yaw_prior` ± `yaw_sigma`) and an odometry prior pose with its covariance.
5. **Loss detection**: too few wall points, a large residual, a low share of explained
   points, candidates the priors cannot separate (best probability under `min_separation`),
   an unobservable direction with no prior to fill it, a pose outside the hint box, a pose
   the priors chose that the scan fits clearly worse than one they rule out (a wrong hint),
   or disagreement with the yaw prior (beyond `yaw_gate` sigmas) or with odometry
   (Mahalanobis distance beyond `odometry_gate`) -> `lost` with a `reason`, `pose` None.
   Otherwise the confidence is a product of factors in 0..1 and at least `HIGH_CONFIDENCE`.
6. **Tilt** (`relevel=True`, the default): when the scan is lost or looks tilted
   (`relevel.suspect_tilt`: missing echoes, returns above the walls or under the floor, an
   attitude the raked arena does not allow), `relevel.relevel` searches the LIDAR's true
   tilt; when it finds one, the re-levelled scan is localized (its covariance widened by
   the tilt's uncertainty) and the correction is in `Localization.relevel` for the AHRS
   and the gimbal to apply. A scan that looks tilted whose tilt cannot be found is `lost`.

`Localizer` keeps the pose between scans: `predict(dx, dy, dyaw)` with the odometry the
caller integrates from its drive commands (robot frame, since the last call), `update(record)`
corrects it with the scan (a Kalman update with the scan's covariance, gated by the same loss
checks; while lost the estimate is dead-reckoned), `initialise(record, hint=...)` and
`relocalize(record)` search globally (the recovery after a loss).

API (all angles radians, arena frame of SPEC 6.1; nothing here reads a clock or does I/O)::

    HIGH_CONFIDENCE = 0.5      a pose is reported (lost False) iff confidence >= this
    YAW_SIGMA = radians(15)    default one-sigma of an AHRS yaw prior
    Pose(x, y, yaw)            NamedTuple, footprint centre (m) and yaw (rad)
    PosePrior(pose, cov)       an odometry pose and its 3x3 covariance (m^2, rad^2)
    localize(record, *, hint=None, yaw_prior=None, yaw_sigma=YAW_SIGMA, prior=None,
             relevel=True, params=None, arena_map=None) -> Localization
    Localization: pose (Pose | None), confidence (0..1), lost, reason ("" unless lost),
                  candidates (Candidate, ...), wall_points, residual_rms (m),
                  covariance (3x3 | None), segments (lines.Segment in the level frame),
                  relevel (relevel.Relevel | None), best (the most probable candidate)
    Candidate: pose, quality, inliers, rms, through, probability, note (why rejected)
    Localizer(params=None, odometry=OdometryNoise(), arena_map=None, yaw_sigma=YAW_SIGMA,
              relevel=True)
        .initialise(record, *, hint=None, yaw_prior=None, yaw_sigma=None) -> Localization
        .predict(dx, dy, dyaw)                      robot-frame motion since the last call
        .update(record, *, yaw_prior=record.yaw, yaw_sigma=None) -> Localization
        .relocalize(record, *, yaw_prior=record.yaw, yaw_sigma=None) -> Localization
        .pose, .covariance, .lost, .last
    wall_points(record, params=None, arena_map=None) -> WallPoints(xy, beams, sensor, total)
    ArenaMap(length, width, wall_height, wall_top, robot_length, robot_width)
    LocalizerParams(...), OdometryNoise(...): the thresholds, each with its reason
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt

from ramp.autonomy import arena
from ramp.autonomy.perception.lines import LineParams, Segment, extract_lines
from ramp.autonomy.perception.records import ScanRecord

if TYPE_CHECKING:
    from ramp.autonomy.perception.relevel import Relevel

FloatArray = npt.NDArray[np.float64]

#: A pose is reported (not lost) only at or above this confidence; the mission treats
#: anything below as lost. Every `Localization` with `lost` False has confidence >= it.
HIGH_CONFIDENCE = 0.5

#: Default one-sigma uncertainty of an AHRS yaw prior (the SPEC lets it drift up to ~20 deg).
YAW_SIGMA = math.radians(15.0)

HINTS = arena.START_BOXES

#: A tilt smaller than this found by re-levelling counts as level (see `relevel`).
RELEVEL_MIN_TILT = math.radians(1.0)


class Pose(NamedTuple):
    """A robot pose in the arena frame: footprint centre (m) and yaw (rad, CCW from +x)."""

    x: float
    y: float
    yaw: float


@dataclass(frozen=True, eq=False)
class PosePrior:
    """A pose believed before the scan (odometry) and its 3x3 covariance (m^2, rad^2)."""

    pose: Pose
    cov: FloatArray


@dataclass(frozen=True)
class ArenaMap:
    """The walls the localizer matches: a rectangle 0..length x 0..width (SPEC 6.1)."""

    length: float = arena.ARENA_LENGTH_M
    width: float = arena.ARENA_WIDTH_M
    wall_height: float = arena.WALL_HEIGHT_M  # at least; beams over it see nothing
    # The highest a wall can be (m): a return above it is not a wall. SPEC 6.1 says "at
    # least 1 m"; the RMC's walls are about that. Raise it (or make it inf) for taller walls:
    # re-levelling then cannot rule out a LIDAR tipped up from walls it still sees.
    wall_top: float = arena.WALL_HEIGHT_M + 0.1
    robot_length: float = arena.ROBOT_LENGTH_M
    robot_width: float = arena.ROBOT_WIDTH_M

    @property
    def normals(self) -> FloatArray:
        """Outward unit normals of the walls x=length, y=width, x=0, y=0 (in that order:
        the wall faced at yaw 0, 90, 180, 270 degrees)."""
        return np.array(((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)))

    @property
    def offsets(self) -> FloatArray:
        """Each wall is {p : normal . p = offset}; inside the arena normal . p < offset."""
        return np.array((self.length, self.width, 0.0, 0.0))

    def hint_box(self, hint: str) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1) of a start box (SPEC 6.1: right y < 1.94, left y >= 1.94)."""
        if hint == "left":
            return 0.0, arena.START_END_X_M, arena.START_SPLIT_Y_M, self.width
        if hint == "right":
            return 0.0, arena.START_END_X_M, 0.0, arena.START_SPLIT_Y_M
        raise ValueError(f"unknown start box {hint!r} (expected left or right)")


@dataclass(frozen=True)
class LocalizerParams:
    """Thresholds of the localizer. Distances in metres, angles in radians."""

    lines: LineParams = field(default_factory=LineParams)
    footprint_margin: float = 0.05  # returns this close to the footprint are the robot
    min_wall_z: float = 0.25  # level-frame height below which a return is ground or rock
    max_wall_z: float = 2.5  # above this it is not our walls (over-the-wall returns)
    min_points: int = 30  # fewer usable returns: nothing to localize with
    axis_tol: float = math.radians(6.0)  # a segment this close to the dominant axes is a wall
    min_segment_length: float = 0.4  # shorter segments do not make candidates
    cluster_tol: float = 0.12  # wall offsets this close are one hypothesis
    inlier_gate: float = 0.08  # a point this close to a wall is explained by it
    through_gate: float = 0.20  # a point this far beyond a wall was seen through it
    through_weight: float = 4.0  # a see-through point counts against this many inliers
    huber: float = 0.03
    feasible_slack: float = 0.15  # the footprint may poke this far out of the arena
    hint_margin: float = 0.15  # a hinted pose may lie this far outside its box
    quality_scale: float = 0.02  # candidates' weights fall by e per this much quality
    quality_gap: float = 0.08  # a chosen pose explaining this much less than the best: lost
    # loss detection
    min_wall_points: int = 40
    max_rms: float = 0.05
    min_quality: float = 0.5
    min_separation: float = 0.9  # the best candidate's probability among them
    max_position_sigma: float = 0.10  # along the least observed direction
    yaw_gate: float = 3.0  # sigmas of the yaw prior
    odometry_gate: float = 16.3  # Mahalanobis^2, chi2(3) at 0.999
    # covariance floors (what the model does not capture: mount errors, wall flatness)
    sigma_floor_xy: float = 0.015
    sigma_floor_yaw: float = math.radians(0.4)


@dataclass(frozen=True)
class Candidate:
    """A pose the scan allows, refined, with how well it explains the scan."""

    pose: Pose
    quality: float  # (inliers - through_weight * through) / points, <= 1
    inliers: int
    rms: float  # m, of the inliers
    through: int  # points seen beyond a wall from this pose
    probability: float = 0.0  # among the feasible candidates, with the priors
    note: str = ""  # why it was rejected, when it was


@dataclass(frozen=True, eq=False)
class Localization:
    """The answer of one localization. `pose` is None exactly when `lost`."""

    pose: Pose | None
    confidence: float
    lost: bool
    reason: str  # "" unless lost
    candidates: tuple[Candidate, ...] = ()
    wall_points: int = 0  # inliers of the chosen (or best) candidate
    residual_rms: float = math.nan
    covariance: FloatArray | None = None
    segments: tuple[Segment, ...] = ()  # in the level frame, for plots
    relevel: Relevel | None = None  # a tilt correction found in this scan, if one was

    @property
    def best(self) -> Candidate | None:
        """The most probable candidate, reported or not (for plots and logs)."""
        if not self.candidates:
            return None
        return max(self.candidates, key=lambda c: (c.probability, c.quality))


# ---- scan preparation -------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class WallPoints:
    """The returns a localization uses, in the level frame."""

    xy: FloatArray  # (m, 2)
    beams: npt.NDArray[np.intp]  # (m,) beam index of each
    sensor: tuple[float, float]  # the LIDAR's x, y in the level frame
    total: int  # valid returns before filtering


def wall_points(record: ScanRecord, params: LocalizerParams | None = None,
                arena_map: ArenaMap | None = None) -> WallPoints:
    """The record's returns that can be walls: not the robot itself, not ground or rocks."""
    p = params if params is not None else LocalizerParams()
    a = arena_map if arena_map is not None else ArenaMap()
    beams = np.nonzero(record.valid)[0]
    chassis = record.points_chassis()
    level = record.points_level()
    hx = a.robot_length / 2.0 + p.footprint_margin
    hy = a.robot_width / 2.0 + p.footprint_margin
    own = (np.abs(chassis[:, 0]) <= hx) & (np.abs(chassis[:, 1]) <= hy)
    keep = ~own & (level[:, 2] >= p.min_wall_z) & (level[:, 2] <= p.max_wall_z)
    sensor = _sensor_level(record)
    return WallPoints(level[keep, :2], beams[keep], (sensor[0], sensor[1]), int(beams.size))


def _sensor_level(record: ScanRecord) -> FloatArray:
    from ramp.autonomy.mount import rotation_zyx

    tilt = np.asarray(rotation_zyx(record.roll, record.pitch, 0.0))
    out: FloatArray = tilt @ np.asarray(record.lidar_position, dtype=np.float64)
    return out


# ---- geometry helpers ---------------------------------------------------------------------------


def _wrap(a: float) -> float:
    return math.remainder(a, 2.0 * math.pi)


def _rot(yaw: float) -> FloatArray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array(((c, -s), (s, c)))


def _signed(xy: FloatArray, pose: Pose, a: ArenaMap) -> FloatArray:
    """(m, 4) signed distance of each point (robot level frame) beyond each wall."""
    world = xy @ _rot(pose.yaw).T + np.array((pose.x, pose.y))
    out: FloatArray = world @ a.normals.T - a.offsets
    return out


def _feasible(pose: Pose, a: ArenaMap, slack: float) -> bool:
    """The footprint lies inside the arena, give or take `slack`."""
    c, s = abs(math.cos(pose.yaw)), abs(math.sin(pose.yaw))
    ex = a.robot_length / 2.0 * c + a.robot_width / 2.0 * s
    ey = a.robot_length / 2.0 * s + a.robot_width / 2.0 * c
    return (ex - slack <= pose.x <= a.length - ex + slack
            and ey - slack <= pose.y <= a.width - ey + slack)


def _in_box(pose: Pose, box: tuple[float, float, float, float], margin: float) -> bool:
    x0, x1, y0, y1 = box
    return x0 - margin <= pose.x <= x1 + margin and y0 - margin <= pose.y <= y1 + margin


# ---- candidates -------------------------------------------------------------------------------


def dominant_axis(segments: Sequence[Segment], tol: float) -> float | None:
    """The segments' common direction modulo 90 degrees (rad, in [0, pi/2)), weighted by
    their point counts; None without segments."""
    if not segments:
        return None
    ang = np.array([s.normal_angle for s in segments])
    w = np.array([float(s.count) * s.length for s in segments])
    four = np.exp(4j * ang)  # directions modulo 90 degrees as unit complex numbers
    # The segment with the most support from the others (within tol) sets the axis.
    close = np.abs(np.angle(four[:, None] * np.conj(four[None, :]))) <= 4.0 * tol
    support = close @ w
    k = int(np.argmax(support))
    mean = np.angle(np.sum(w[close[k]] * four[close[k]])) / 4.0
    return float(mean % (math.pi / 2.0))


def _axis_values(segments: Sequence[Segment], yaw: float, a: ArenaMap, axis_tol: float,
                 cluster_tol: float) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
    """For a yaw: hypotheses (value, weight) for x and for y, each from the walls the
    segments would be at that yaw; values from opposite walls that agree are joined."""
    per_wall: list[list[tuple[float, float]]] = [[], [], [], []]
    rot = _rot(yaw)
    for s in segments:
        ang = _wrap(s.normal_angle + yaw)
        k = round(ang / (math.pi / 2.0)) % 4
        if abs(_wrap(ang - k * math.pi / 2.0)) > axis_tol:
            continue
        mid = rot @ np.asarray(s.midpoint)
        n = a.normals[k]
        # n . (pose + mid) = offset  ->  the pose's coordinate along n
        value = (a.offsets[k] - float(n @ mid)) * float(n[0] + n[1])
        per_wall[k].append((value, float(s.count)))
    xs = _cluster(per_wall[0] + per_wall[2], cluster_tol)
    ys = _cluster(per_wall[1] + per_wall[3], cluster_tol)
    return xs, ys


def _cluster(values: list[tuple[float, float]], tol: float) -> list[tuple[float, float]]:
    """Group (value, weight) pairs closer than `tol`: weighted means and summed weights,
    heaviest first."""
    out: list[tuple[float, float]] = []
    for v, w in sorted(values):
        if out and v - out[-1][0] <= tol:
            mv, mw = out[-1]
            out[-1] = ((mv * mw + v * w) / (mw + w), mw + w)
        else:
            out.append((v, w))
    return sorted(out, key=lambda vw: -vw[1])


def seed_poses(segments: Sequence[Segment], a: ArenaMap, params: LocalizerParams,
               prior: Pose | None = None, max_per_axis: int = 3) -> list[Pose]:
    """Every pose the segments allow: four yaws from their dominant axis, and for each the
    x and y the matched walls give. A coordinate no wall fixes comes from `prior` when
    there is one (else no pose for that yaw)."""
    long_ones = [s for s in segments if s.length >= params.min_segment_length]
    axis = dominant_axis(long_ones, params.axis_tol)
    if axis is None:
        return []
    out: list[Pose] = []
    for k in range(4):
        yaw = _wrap(-axis + k * math.pi / 2.0)
        xs, ys = _axis_values(long_ones, yaw, a, params.axis_tol, params.cluster_tol)
        x_opts = [v for v, _ in xs[:max_per_axis]] or ([prior.x] if prior else [])
        y_opts = [v for v, _ in ys[:max_per_axis]] or ([prior.y] if prior else [])
        out.extend(Pose(x, y, yaw) for x in x_opts for y in y_opts)
    return out


# ---- refinement and scoring ---------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Fit:
    pose: Pose
    info: FloatArray  # 3x3 information (J^T J over inliers, per unit variance)
    inliers: int
    rms: float
    through: int
    quality: float


def refine(xy: FloatArray, pose: Pose, a: ArenaMap, params: LocalizerParams,
           iterations: int = 12) -> Fit:
    """Point-to-wall Gauss-Newton from `pose`: each point pulls towards its nearest wall
    (gated, Huber-weighted); directions with no information are left where they are."""
    gates = (0.4, 0.25, 0.15, params.inlier_gate)
    final = fit_pose(xy, pose, a, gates, params.huber, iterations)
    return score(xy, final, a, params)


def fit_pose(xy: FloatArray, pose: Pose, a: ArenaMap, gates: Sequence[float],
             huber: float, iterations: int) -> Pose:
    """The Gauss-Newton iterations of `refine`, gate k at iteration k (the last one after)."""
    x, y, yaw = pose
    for it in range(iterations):
        gate = gates[min(it, len(gates) - 1)]
        r, _, n, rel = _residuals(xy, Pose(x, y, yaw), a)
        use = np.abs(r) < gate
        if int(use.sum()) < 3:
            break
        ru, nu, relu = r[use], n[use], rel[use]
        jac = _jacobian(nu, relu)
        absr = np.abs(ru)
        w = np.where(absr <= huber, 1.0, huber / np.maximum(absr, 1e-12))
        jw = jac * w[:, None]
        h = jac.T @ jw
        g = jw.T @ ru
        # A tiny ridge leaves unobservable directions (one wall in view) where they are.
        ridge = 1e-9 * (float(np.trace(h)) + 1e-12)
        step = -np.linalg.solve(h + ridge * np.eye(3), g)
        x, y, yaw = x + float(step[0]), y + float(step[1]), _wrap(yaw + float(step[2]))
        if it >= len(gates) and abs(step[0]) + abs(step[1]) < 1e-5 and abs(step[2]) < 1e-6:
            break
    return Pose(float(x), float(y), float(yaw))


def _residuals(xy: FloatArray, pose: Pose, a: ArenaMap,
               ) -> tuple[FloatArray, npt.NDArray[np.intp], FloatArray, FloatArray]:
    """Signed distance to the nearest wall, its index, its normal, and the points turned
    into the arena's orientation (not moved)."""
    rel = xy @ _rot(pose.yaw).T
    d = (rel + np.array((pose.x, pose.y))) @ a.normals.T - a.offsets
    j = np.argmax(d, axis=1)
    r = d[np.arange(d.shape[0]), j]
    return r, j, a.normals[j], rel


def _jacobian(n: FloatArray, rel: FloatArray) -> FloatArray:
    """d residual / d (x, y, yaw) for point-to-wall residuals n . (R p + t) - c."""
    dyaw = n[:, 0] * -rel[:, 1] + n[:, 1] * rel[:, 0]
    return np.column_stack((n[:, 0], n[:, 1], dyaw))


def score(xy: FloatArray, pose: Pose, a: ArenaMap, params: LocalizerParams) -> Fit:
    """How well `pose` explains the points: inliers, their RMS, see-through points."""
    r, _, n, rel = _residuals(xy, pose, a)
    m = max(1, xy.shape[0])
    inl = np.abs(r) < params.inlier_gate
    through = int((r > params.through_gate).sum())
    k = int(inl.sum())
    rms = float(np.sqrt(np.mean(r[inl] ** 2))) if k else math.inf
    jac = _jacobian(n[inl], rel[inl])
    info = jac.T @ jac
    quality = (k - params.through_weight * through) / m
    return Fit(pose, info, k, rms, through, float(quality))


def covariance(fit: Fit, params: LocalizerParams, sigma: float = 0.01) -> FloatArray:
    """The pose covariance of a fit: residual variance over information, plus floors.
    Unobservable directions get a huge variance (1e6)."""
    var = max(fit.rms if math.isfinite(fit.rms) else 0.0, sigma) ** 2
    vals, vecs = np.linalg.eigh(fit.info)
    inv = np.where(vals > 1e-6 * max(float(vals.max()), 1e-12), 1.0 / np.maximum(vals, 1e-300),
                   1e6 / var)
    cov: FloatArray = var * (vecs * inv) @ vecs.T
    cov += np.diag((params.sigma_floor_xy ** 2, params.sigma_floor_xy ** 2,
                    params.sigma_floor_yaw ** 2))
    return cov


def position_sigma(cov: FloatArray) -> float:
    """Standard deviation along the least certain horizontal direction."""
    return float(math.sqrt(max(0.0, float(np.linalg.eigvalsh(cov[:2, :2]).max()))))


# ---- one localization ------------------------------------------------------------------------


def localize(record: ScanRecord, *, hint: str | None = None, yaw_prior: float | None = None,
             yaw_sigma: float = YAW_SIGMA, prior: PosePrior | None = None,
             relevel: bool = True, params: LocalizerParams | None = None,
             arena_map: ArenaMap | None = None) -> Localization:
    """Localize one scan against the arena's walls (see the module's docstring).

    `hint`: "left"/"right", the start box the robot is in (initialisation). `yaw_prior`
    (rad) with one-sigma `yaw_sigma`: the AHRS yaw. `prior`: the odometry pose and its
    covariance. `relevel`: when the scan is lost or looks tilted (`relevel.suspect_tilt`),
    search for the LIDAR's true tilt and localize the re-levelled scan; without a clear
    tilt, a scan that looks tilted is reported lost. Pure: the same inputs, the same answer.
    """
    p = params if params is not None else LocalizerParams()
    a = arena_map if arena_map is not None else ArenaMap()
    if hint is not None and hint not in HINTS:
        raise ValueError(f"unknown start box {hint!r} (expected left or right)")
    first = _localize_2d(record, hint, yaw_prior, yaw_sigma, prior, p, a)
    if not relevel:
        return first
    from ramp.autonomy.perception import relevel as rl

    check = rl.suspect_tilt(record, first.pose, arena_map=a, params=p)
    if not first.lost and not check.suspect:
        return first
    fix = rl.relevel(record, first=first, hint=hint, yaw_prior=yaw_prior, yaw_sigma=yaw_sigma,
                     prior=prior, params=p, arena_map=a)
    if fix.found:
        again = _localize_2d(fix.apply(record), hint, yaw_prior, yaw_sigma, prior, p, a)
        if again.lost:
            again = replace(again, reason=f"{again.reason} (after re-levelling by "
                                          f"{math.degrees(fix.tilt):.1f} deg)")
            return replace(again, relevel=fix)
        return _tilt_uncertain(replace(again, relevel=fix), record, p)
    if first.lost or fix.tilt < RELEVEL_MIN_TILT:
        # Lost anyway, or the scan is best explained level: the suspicion is refuted.
        return replace(first, relevel=fix)
    return replace(first, pose=None, lost=True,
                   confidence=min(first.confidence, HIGH_CONFIDENCE * 0.98),
                   reason=f"the scan looks tilted ({'; '.join(check.reasons)}) and its tilt "
                          f"cannot be found: {fix.reason}", relevel=fix)


def _tilt_uncertain(res: Localization, record: ScanRecord, p: LocalizerParams) -> Localization:
    """A re-levelled pose carries the tilt's uncertainty: an attitude error of e moves the
    LIDAR by its height x sin(e) across the floor, which the walls cannot see."""
    if res.relevel is None or res.covariance is None:
        return res
    height = abs(float(record.lidar_position[2]))
    shift = height * math.sin(min(max(res.relevel.sigma), math.pi / 2))
    cov = res.covariance.copy()
    cov[:2, :2] += np.eye(2) * shift ** 2
    sigma = position_sigma(cov)
    if sigma > p.max_position_sigma:
        return replace(res, pose=None, lost=True, covariance=cov,
                       confidence=min(res.confidence, HIGH_CONFIDENCE * 0.98),
                       reason=f"re-levelled, but the tilt is too uncertain for the position "
                              f"({sigma:.2f} m sigma)")
    return replace(res, covariance=cov)


def _localize_2d(record: ScanRecord, hint: str | None, yaw_prior: float | None,
                 yaw_sigma: float, prior: PosePrior | None, p: LocalizerParams,
                 a: ArenaMap) -> Localization:
    pts = wall_points(record, p, a)
    if pts.xy.shape[0] < p.min_points:
        return _lost(f"too few returns to localize ({pts.xy.shape[0]} usable of "
                     f"{pts.total})")
    segs = extract_lines(pts.xy, pts.beams, pts.sensor, p.lines)
    return localize_points(pts.xy, tuple(segs), hint=hint, yaw_prior=yaw_prior,
                           yaw_sigma=yaw_sigma, prior=prior, params=p, arena_map=a)


def localize_points(xy: FloatArray, segments: tuple[Segment, ...], *, hint: str | None = None,
                    yaw_prior: float | None = None, yaw_sigma: float = YAW_SIGMA,
                    prior: PosePrior | None = None, params: LocalizerParams | None = None,
                    arena_map: ArenaMap | None = None) -> Localization:
    """`localize` on prepared level-frame points (m, 2) and their segments."""
    p = params if params is not None else LocalizerParams()
    a = arena_map if arena_map is not None else ArenaMap()
    seeds = seed_poses(segments, a, p, prior.pose if prior is not None else None)
    if prior is not None:
        seeds.append(prior.pose)
    if not seeds:
        if segments:
            return _lost("only walls along one direction in view: the position along them "
                         "is unobservable", segments=segments)
        return _lost("no straight wall in view", segments=segments)

    fits = _unique([refine(xy, s, a, p) for s in _promising(xy, seeds, a, p)])
    box = a.hint_box(hint) if hint is not None else None
    notes: list[str] = []
    logw: list[float] = []  # log weights: odometry far off must not underflow to zero
    best_quality = max((f.quality for f in fits), default=-math.inf)
    for f in fits:
        note = ""
        if not _feasible(f.pose, a, p.feasible_slack):
            note = "the robot would stand outside the arena"
        elif box is not None and not _in_box(f.pose, box, p.hint_margin):
            note = f"outside the {hint} start box"
        lw = -math.inf
        if not note:
            lw = (f.quality - best_quality) / p.quality_scale
            if yaw_prior is not None:
                z = _wrap(f.pose.yaw - yaw_prior) / yaw_sigma
                lw -= 0.5 * z * z
            if prior is not None:
                lw -= 0.5 * _mahalanobis2(f, prior, p)
        notes.append(note)
        logw.append(lw)
    top = max(logw)
    weights = [math.exp(w - top) if math.isfinite(w) else 0.0 for w in logw]
    total = sum(weights)
    probs = [w / total if total > 0 else 0.0 for w in weights]
    cands = tuple(Candidate(f.pose, f.quality, f.inliers, f.rms, f.through, pr, note)
                  for f, pr, note in zip(fits, probs, notes, strict=True))
    if total <= 0.0:
        why = "; ".join(sorted({n for n in notes if n}))
        return _lost(f"no acceptable pose: {why}", candidates=cands, segments=segments)

    k = int(np.argmax(probs))
    best = fits[k]
    cov = covariance(best, p)
    fused_pose, fused_cov = best.pose, cov
    if prior is not None:
        fused_pose, fused_cov = kalman_update(prior.pose, prior.cov, best.pose, cov)
    factors, failures = _judge(best, probs[k], fused_cov, yaw_prior, yaw_sigma, prior, cov, p)
    if best_quality - best.quality > p.quality_gap:
        # The priors chose a pose the scan fits clearly worse than another one: a wrong
        # start box, or a yaw prior far off. Do not believe either; say so.
        failures.append(f"the scan fits a pose the priors rule out better (explains "
                        f"{best_quality * 100:.0f}% of it, the chosen one "
                        f"{max(best.quality, 0.0) * 100:.0f}%)")
    conf = float(np.prod([v for v, _ in factors]))
    if failures or conf < HIGH_CONFIDENCE:
        reason = "; ".join(failures) if failures else min(factors)[1]
        return Localization(None, min(conf, HIGH_CONFIDENCE * 0.98), True, reason, cands,
                            best.inliers, best.rms, cov, segments)
    return Localization(fused_pose, conf, False, "", cands, best.inliers, best.rms, fused_cov,
                        segments)


def _promising(xy: FloatArray, seeds: list[Pose], a: ArenaMap, p: LocalizerParams,
               margin: float = 0.25) -> list[Pose]:
    """The seeds worth refining: a quick score on every 4th point drops those that explain
    far less of the scan than the best one (refinement moves a seed a few centimetres, it
    does not turn a see-through pose into a good one)."""
    sub = xy[::4]
    loose = replace(p, inlier_gate=0.15)
    q = [score(sub, s, a, loose).quality for s in seeds]
    top = max(q)
    return [s for s, qs in zip(seeds, q, strict=True) if qs >= top - margin]


def _judge(best: Fit, prob: float, fused_cov: FloatArray, yaw_prior: float | None,
           yaw_sigma: float, prior: PosePrior | None, cov: FloatArray,
           p: LocalizerParams) -> tuple[list[tuple[float, str]], list[str]]:
    """Confidence factors (value, what lowers it) and the hard failures of a best fit."""
    failures: list[str] = []
    if best.inliers < p.min_wall_points:
        failures.append(f"too few wall points ({best.inliers} < {p.min_wall_points})")
    if best.rms > p.max_rms:
        failures.append(f"large residuals ({best.rms * 100:.1f} cm RMS)")
    if best.quality < p.min_quality:
        failures.append(f"the map explains only {max(best.quality, 0.0) * 100:.0f}% of "
                        "the scan")
    if prob < p.min_separation:
        failures.append(f"symmetric candidates the priors cannot separate (best "
                        f"{prob:.2f})")
    sigma = position_sigma(fused_cov)
    if sigma > p.max_position_sigma:
        failures.append(f"position unobservable from the walls in view ({sigma:.2f} m "
                        "sigma)")
    yaw_factor = 1.0
    if yaw_prior is not None:
        z = abs(_wrap(best.pose.yaw - yaw_prior)) / yaw_sigma
        if z > p.yaw_gate:
            failures.append(f"disagrees with the yaw prior by "
                            f"{math.degrees(z * yaw_sigma):.0f} deg")
        yaw_factor = math.exp(-0.5 * max(0.0, z * z - 4.0))
    odo_factor = 1.0
    if prior is not None:
        m2 = _mahalanobis2_cov(best.pose, cov, prior)
        if m2 > p.odometry_gate:
            d = math.hypot(best.pose.x - prior.pose.x, best.pose.y - prior.pose.y)
            failures.append(f"disagrees with odometry ({d:.2f} m, "
                            f"{math.degrees(abs(_wrap(best.pose.yaw - prior.pose.yaw))):.0f} "
                            "deg off)")
        odo_factor = math.exp(-0.5 * max(0.0, m2 - 7.8))
    factors = [
        (prob, "symmetric candidates"),
        (min(1.0, best.inliers / (2.0 * p.min_wall_points)), "few wall points"),
        (float(np.clip((1.2 * p.max_rms - best.rms) / (0.6 * p.max_rms), 0.0, 1.0)),
         "large residuals"),
        (float(np.clip((best.quality - 0.3) / 0.4, 0.0, 1.0)), "unexplained returns"),
        (float(np.clip((1.5 * p.max_position_sigma - sigma) / p.max_position_sigma, 0.0,
                       1.0)), "weakly observable position"),
        (yaw_factor, "yaw prior disagreement"),
        (odo_factor, "odometry disagreement"),
    ]
    return factors, failures


def _mahalanobis2(f: Fit, prior: PosePrior, p: LocalizerParams) -> float:
    return _mahalanobis2_cov(f.pose, covariance(f, p), prior)


def _mahalanobis2_cov(pose: Pose, cov: FloatArray, prior: PosePrior) -> float:
    d = np.array((pose.x - prior.pose.x, pose.y - prior.pose.y, _wrap(pose.yaw - prior.pose.yaw)))
    s = np.asarray(prior.cov) + cov
    return float(d @ np.linalg.solve(s, d))


def kalman_update(pose: Pose, cov: FloatArray, meas: Pose, meas_cov: FloatArray,
                  ) -> tuple[Pose, FloatArray]:
    """Fuse a predicted pose with a measured one (both full 3x3 covariances)."""
    p = np.asarray(cov, dtype=np.float64)
    s = p + meas_cov
    gain = p @ np.linalg.inv(s)
    d = np.array((meas.x - pose.x, meas.y - pose.y, _wrap(meas.yaw - pose.yaw)))
    x = np.array(pose) + gain @ d
    new = (np.eye(3) - gain) @ p
    new = 0.5 * (new + new.T)
    return Pose(float(x[0]), float(x[1]), _wrap(float(x[2]))), new


def _unique(fits: list[Fit], dxy: float = 0.05, dyaw: float = math.radians(2.0)) -> list[Fit]:
    """Drop refined poses that converged onto one another (keep the better one)."""
    out: list[Fit] = []
    for f in sorted(fits, key=lambda f: -f.quality):
        if all(math.hypot(f.pose.x - g.pose.x, f.pose.y - g.pose.y) > dxy
               or abs(_wrap(f.pose.yaw - g.pose.yaw)) > dyaw for g in out):
            out.append(f)
    return out


def _lost(reason: str, candidates: tuple[Candidate, ...] = (),
          segments: tuple[Segment, ...] = ()) -> Localization:
    return Localization(None, 0.0, True, reason, candidates, 0, math.nan, None, segments)


# ---- tracking between scans ---------------------------------------------------------------------


@dataclass(frozen=True)
class OdometryNoise:
    """How uncertain the drive's dead reckoning is (skid steering slips, mostly in turns)."""

    per_metre: float = 0.05  # sigma of the distance travelled, per metre
    lateral_per_metre: float = 0.03  # sideways slip, per metre
    yaw_per_rad: float = 0.10  # sigma of a turn, per radian turned
    yaw_per_metre: float = math.radians(2.0)  # heading wander per metre driven
    floor_xy: float = 0.002  # per call, m
    floor_yaw: float = math.radians(0.05)


class Localizer:
    """The robot's pose between scans: odometry predicts, the walls correct.

    Deterministic and I/O-free; the caller owns the clock and calls `predict` with the
    motion it commanded and `update` with each scan it wants localized.
    """

    def __init__(self, params: LocalizerParams | None = None,
                 odometry: OdometryNoise | None = None, arena_map: ArenaMap | None = None,
                 yaw_sigma: float = YAW_SIGMA, relevel: bool = True) -> None:
        self.params = params if params is not None else LocalizerParams()
        self.odometry = odometry if odometry is not None else OdometryNoise()
        self.arena = arena_map if arena_map is not None else ArenaMap()
        self.yaw_sigma = yaw_sigma
        self.relevel = relevel
        self._pose: Pose | None = None
        self._cov: FloatArray | None = None
        self.lost = True  # until a confident fix
        self.last: Localization | None = None

    @property
    def pose(self) -> Pose | None:
        """The current estimate (dead-reckoned while lost), None before the first fix."""
        return self._pose

    @property
    def covariance(self) -> FloatArray | None:
        return None if self._cov is None else self._cov.copy()

    def initialise(self, record: ScanRecord, *, hint: str | None = None,
                   yaw_prior: float | None = None, yaw_sigma: float | None = None,
                   ) -> Localization:
        """Global localization (no pose prior), e.g. in the start box with `hint`."""
        return self._global(record, hint, yaw_prior, yaw_sigma)

    def relocalize(self, record: ScanRecord, *, yaw_prior: float | None = None,
                   yaw_sigma: float | None = None) -> Localization:
        """Forget the pose prior and search globally (recovery after a loss); the yaw
        prior defaults to the record's AHRS yaw."""
        if yaw_prior is None:
            yaw_prior = record.yaw
        return self._global(record, None, yaw_prior, yaw_sigma)

    def predict(self, dx: float, dy: float, dyaw: float) -> None:
        """Move the estimate by a robot-frame motion (forward dx, left dy, turn dyaw) since
        the last call, and grow its covariance accordingly."""
        if self._pose is None or self._cov is None:
            return
        x, y, yaw = self._pose
        c, s = math.cos(yaw), math.sin(yaw)
        nx, ny = x + c * dx - s * dy, y + s * dx + c * dy
        f = np.array(((1.0, 0.0, -s * dx - c * dy), (0.0, 1.0, c * dx - s * dy),
                      (0.0, 0.0, 1.0)))
        o = self.odometry
        dist = math.hypot(dx, dy)
        q_robot = np.diag(((o.per_metre * dist + o.floor_xy) ** 2,
                           (o.lateral_per_metre * dist + o.floor_xy) ** 2,
                           (o.yaw_per_rad * abs(dyaw) + o.yaw_per_metre * dist
                            + o.floor_yaw) ** 2))
        g = np.eye(3)
        g[:2, :2] = _rot(yaw)
        self._cov = f @ self._cov @ f.T + g @ q_robot @ g.T
        self._pose = Pose(nx, ny, _wrap(yaw + dyaw))

    def update(self, record: ScanRecord, *, yaw_prior: float | None = None,
               yaw_sigma: float | None = None) -> Localization:
        """Correct the estimate with one scan. The yaw prior defaults to the record's AHRS
        yaw; the pose prior is the current estimate. With no estimate yet this is a global
        localization."""
        if yaw_prior is None:
            yaw_prior = record.yaw
        if self._pose is None or self._cov is None:
            return self._global(record, None, yaw_prior, yaw_sigma)
        sigma = self.yaw_sigma if yaw_sigma is None else yaw_sigma
        res = localize(record, yaw_prior=yaw_prior, yaw_sigma=sigma,
                       prior=PosePrior(self._pose, self._cov), relevel=self.relevel,
                       params=self.params, arena_map=self.arena)
        return self._accept(res)

    def _global(self, record: ScanRecord, hint: str | None, yaw_prior: float | None,
                yaw_sigma: float | None) -> Localization:
        sigma = self.yaw_sigma if yaw_sigma is None else yaw_sigma
        res = localize(record, hint=hint, yaw_prior=yaw_prior, yaw_sigma=sigma,
                       relevel=self.relevel, params=self.params, arena_map=self.arena)
        return self._accept(res)

    def _accept(self, res: Localization) -> Localization:
        self.last = res
        self.lost = res.lost
        if res.lost or res.pose is None or res.covariance is None:
            return res
        self._pose, self._cov = res.pose, res.covariance
        return res
