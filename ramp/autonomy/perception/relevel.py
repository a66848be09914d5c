"""The LIDAR's true tilt, found from the scan itself: re-levelling after an AHRS fault.

MARTE's runs 1 and 4 were lost because the gimbal levelled the LIDAR against a wrong gravity
vector (a drifting AHRS, a shifted IMU mount): the scan plane tipped a few degrees, the far
walls went over its top or under the ground, and nothing said so. A tilted scan still
carries the evidence of its tilt:

- **ground returns** where a wall should be: beams tipped down meet the floor at
  h / sin(elevation), a line of points that lies on the plane z = 0 only under the true tilt;
- **missing echoes**: beams tipped up pass over a wall's top (walls are at least
  `ArenaMap.wall_height` tall), so from the bearing where they vanish the tilt follows;
- **wall points** at heights a wall cannot have (above `ArenaMap.wall_top`, under the floor);
- the LIDAR itself displaced by ~0.7 m x sin(error) when the chassis attitude is wrong,
  which an odometry prior can see.

`relevel` explains all of it at once with a 3D model of the arena (four vertical walls up
to `ArenaMap.wall_top`, and the floor): for a few pose candidates (the odometry prior, the
candidates of a first localization, the poses the scan fits best) it scores a grid of
corrections C (tilts up to `max_tilt` about every horizontal axis, the pose moved so the
LIDAR stays where the walls put it), fits the pose to the walls for the best of them, and
polishes the best few by a pattern search in roll and pitch. The cost is a negative
log-likelihood: each echo's squared distance to the model (wall, or floor at least
`floor_wall_gap` inside the walls) in units of `sigma`, capped at an outlier's; one outlier
per missing echo the model says should have come back; a small prior for level; and the
priors on the pose (start box, yaw, odometry), which only rank poses.

The answer is `found` only when it is clear: the tilt is at least `min_tilt`; the scan is
better explained than by any level pose (by `min_gain`), or, when the scan alone cannot
tell (an attitude error moves the LIDAR by ~0.7 m x sin(error), which a pose absorbs), the
scan and agreeing priors are; no other tilt (about another axis, or the mirror image of the
scan plane about the horizontal, which projects onto the floor identically) comes within
`ambiguity_gain`; and the cost's curvature puts roll and pitch within `max_sigma`.

The correction C turns the record's level frame (its believed roll and pitch) into the true
one: true_level = C @ believed_level. The result gives it three ways:

- `roll`, `pitch`: the chassis attitude the scan says (what the AHRS should have reported),
  and `d_roll`, `d_pitch` the change from the record's: add them to the attitude estimate
  (or the IMU's mount offset); `apply(record)` gives the record with the attitude corrected;
- `lidar_pitch_error`, `lidar_roll_error`: how the scan plane is really turned in the
  LIDAR's own axes (nose down, left side up positive); `tilt_correction = -lidar_pitch_error`
  is how much the gimbal's tilt moves when it levels against the corrected attitude
  (positive tilt is nose down, as in `ramp.autonomy.mount`). A pan/tilt gimbal cannot take
  out a roll about the scanner's own axis at pan 0; that part only the attitude fixes.

**Recovery recipe** (for the mission): when a level scan gives no clear tilt (`found`
False, e.g. the walls in view are near and nothing went over a top), tip the gimbal 10-15
deg further down so the floor is in view and `relevel` that scan with the odometry pose as
`prior`: the floor pins the tilt. Then correct the attitude, rescan level and `localize`.

`suspect_tilt(record)` is the quick check: missing echoes (in a closed arena a level beam
always meets something; given a pose, only those the record's own attitude cannot explain),
returns under the floor or above the walls' top, or an attitude the raked arena does not
allow. It returns a `TiltCheck` (true when suspect) with the evidence and, on request with a
pose, a `Relevel`: what the AHRS can use to flag an implausible gravity vector.

API::

    relevel(record, *, first=None, poses=(), hint=None, yaw_prior=None, yaw_sigma=YAW_SIGMA,
            prior=None, params=None, arena_map=None, relevel_params=None) -> Relevel
    Relevel: found, reason, correction (3x3), tilt, roll, pitch, d_roll, d_pitch,
             lidar_roll_error, lidar_pitch_error, tilt_correction (rad), pose (Pose | None),
             cost, level_cost, ground_points, missing_explained, sigma (roll, pitch rad);
             apply(record) -> ScanRecord
    suspect_tilt(record, pose=None, *, estimate=False, arena_map=None, params=None,
                 max_no_echo=0.01, crater_depth=0.35, wall_margin=0.05, min_count=5,
                 max_lean=radians(5)) -> TiltCheck
    TiltCheck: suspect, reasons, no_echo_fraction, below_ground, above_walls,
               estimate (Relevel | None); bool(check) == suspect
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from ramp.autonomy.mount import axis_angle, euler_zyx, rotation_zyx
from ramp.autonomy.perception.localizer import (
    RELEVEL_MIN_TILT,
    YAW_SIGMA,
    ArenaMap,
    Localization,
    LocalizerParams,
    Pose,
    PosePrior,
)
from ramp.autonomy.perception.records import ScanRecord

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class RelevelParams:
    """Tuning of the tilt search. Distances in metres, angles in radians."""

    max_tilt: float = math.radians(12.0)
    tilt_step: float = math.radians(1.5)  # grid rings
    azimuths: int = 24  # grid directions per ring (15 degrees)
    # The cost is a negative log-likelihood: an echo at distance d from the model costs
    # (d / sigma)^2 / 2 up to the cost of an outlier at `tau`; a missing echo the model
    # says should have come back costs `miss_weight` outliers.
    sigma: float = 0.02  # m: range noise and what the model leaves out (terrain, walls)
    tau: float = 0.08  # m: farther than this from the model, an echo is an outlier
    miss_weight: float = 1.0
    wall_top_margin: float = 0.05  # a beam this close under a wall's top may miss it
    # Floor returns at a wall's foot are no evidence of tilt: a wall seen low looks the
    # same (a tilt can lay a whole wall onto the floor just in front of it). Only returns
    # this far inside the walls count as floor.
    floor_wall_gap: float = 0.20
    tilt_sigma: float = math.radians(3.0)  # prior for level: costs (tilt / sigma)^2 / 2
    min_tilt: float = RELEVEL_MIN_TILT  # smaller corrections are not worth reporting
    min_gain: float = 10.0  # the correction must lower the cost this much
    prior_agreement: float = 4.5  # priors' cost (half a Mahalanobis^2) of an agreeing pose
    ambiguity_tilt: float = math.radians(2.5)  # two answers this far apart ...
    ambiguity_gain: float = 6.0  # ... and this close in cost: the scan cannot tell
    # The cost's curvature gives the correction's uncertainty: wider than this in roll or
    # pitch and the scan does not pin the tilt down (walls alone say little about it).
    sigma_step: float = math.radians(1.0)
    max_sigma: float = math.radians(2.0)
    grid_stride: int = 3  # use every n-th echo in the grid stage (speed)
    refine_top: int = 6  # distinct grid hypotheses per pose seed given a fitted pose
    polish_top: int = 4  # of those, the best polished by a pattern search
    max_poses: int = 4


@dataclass(frozen=True, eq=False)
class Relevel:
    """What the scan says about the LIDAR's tilt (see the module's docstring)."""

    found: bool  # a correction of at least `min_tilt` that clearly explains the scan better
    reason: str  # what was found, or why nothing was
    correction: FloatArray  # 3x3, believed level frame -> true level frame
    tilt: float  # rad, the angle of `correction`
    roll: float  # rad, the chassis roll the scan says
    pitch: float  # rad
    d_roll: float  # rad, roll - record.roll
    d_pitch: float  # rad
    lidar_roll_error: float  # rad, the scan plane's roll in the LIDAR's own axes
    lidar_pitch_error: float  # rad, nose down positive
    tilt_correction: float  # rad, add to the gimbal's tilt set-point
    pose: Pose | None = None  # the pose found together with the tilt
    cost: float = math.nan  # model cost with the correction
    level_cost: float = math.nan  # model cost without it (same pose search)
    ground_points: int = 0  # echoes explained as floor under the correction
    missing_explained: int = 0  # missing echoes the correction explains
    sigma: tuple[float, float] = (math.inf, math.inf)  # rad, of the correction's roll, pitch

    def apply(self, record: ScanRecord) -> ScanRecord:
        """The record with the chassis attitude the scan says (roll, pitch)."""
        return replace(record, roll=self.roll, pitch=self.pitch)


@dataclass(frozen=True)
class TiltCheck:
    """Signs that the record's attitude (and so the LIDAR's level) is wrong."""

    suspect: bool
    reasons: tuple[str, ...]
    no_echo_fraction: float  # of the beams not blocked by the robot (unexplained ones,
    # when a pose was given)
    below_ground: int  # returns more than a crater's depth under the floor
    above_walls: int  # returns far above any wall
    estimate: Relevel | None = None

    def __bool__(self) -> bool:
        return self.suspect


# ---- the scan in 3D ----------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Scan3D:
    echoes: FloatArray  # (n, 3) believed level frame, the robot's own frame removed
    misses: FloatArray  # (m, 3) unit directions of beams with no echo, believed level frame
    origin: FloatArray  # (3,) the LIDAR in the believed level frame
    lidar: FloatArray  # (3, 3) LIDAR axes -> believed level frame
    beams: int  # beams in the scan


def _scan3d(record: ScanRecord, lp: LocalizerParams, a: ArenaMap) -> _Scan3D:
    chassis = record.points_chassis()
    hx = a.robot_length / 2.0 + lp.footprint_margin
    hy = a.robot_width / 2.0 + lp.footprint_margin
    own = (np.abs(chassis[:, 0]) <= hx) & (np.abs(chassis[:, 1]) <= hy)
    level = record.points_level()[~own]
    tilt = np.asarray(rotation_zyx(record.roll, record.pitch, 0.0))
    lidar = tilt @ np.asarray(record.lidar_rotation, dtype=np.float64)
    origin = tilt @ np.asarray(record.lidar_position, dtype=np.float64)
    miss = ~record.valid
    ang = record.angles[miss]
    dirs = np.column_stack((np.cos(ang), np.sin(ang), np.zeros_like(ang))) @ lidar.T
    return _Scan3D(level, dirs, origin, lidar, int(record.ranges.size))


def _grid(p: RelevelParams) -> FloatArray:
    """(T, 3, 3) corrections: level, then rings of tilt about every horizontal axis."""
    mats = [np.eye(3)]
    rings = int(round(p.max_tilt / p.tilt_step))
    for i in range(1, rings + 1):
        th = i * p.tilt_step
        for k in range(p.azimuths):
            phi = 2.0 * math.pi * k / p.azimuths
            mats.append(np.asarray(axis_angle((math.cos(phi), math.sin(phi), 0.0), th)))
    return np.stack(mats)


def _angle_of(c: FloatArray) -> float:
    return math.acos(max(-1.0, min(1.0, (float(np.trace(c)) - 1.0) / 2.0)))


def _model_cost(s: _Scan3D, echoes: FloatArray, c: FloatArray, pose: FloatArray, a: ArenaMap,
                p: RelevelParams) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Cost of corrections c (T, 3, 3) with poses (T, 3), and per-hypothesis counts of
    floor echoes and explained misses. Vectorised over hypotheses."""
    x, y, yaw = pose[:, 0], pose[:, 1], pose[:, 2]
    cs, sn = np.cos(yaw), np.sin(yaw)
    pts = np.einsum("tij,nj->tni", c, echoes)  # (T, n, 3)
    wx = cs[:, None] * pts[..., 0] - sn[:, None] * pts[..., 1] + x[:, None]
    wy = sn[:, None] * pts[..., 0] + cs[:, None] * pts[..., 1] + y[:, None]
    z = pts[..., 2]
    beyond = np.maximum.reduce([wx - a.length, wy - a.width, -wx, -wy])  # (T, n)
    big = 10.0
    on_wall = (z > -p.tau) & (z < a.wall_top + p.tau)
    d_wall = np.where(on_wall, np.abs(beyond), big)
    d_floor = np.where(beyond < -p.floor_wall_gap, np.abs(z), big)
    d = np.minimum(d_wall, d_floor)
    outlier = 0.5 * (p.tau / p.sigma) ** 2
    cost = np.minimum(0.5 * (d / p.sigma) ** 2, outlier).sum(axis=1)
    floor = ((d_floor < p.tau) & (d_floor <= d_wall)).sum(axis=1).astype(np.float64)

    explained = np.zeros(c.shape[0])
    if s.misses.shape[0]:
        o = np.einsum("tij,j->ti", c, s.origin)  # (T, 3)
        dirs = np.einsum("tij,mj->tmi", c, s.misses)  # (T, m, 3)
        ox = cs * o[:, 0] - sn * o[:, 1] + x
        oy = sn * o[:, 0] + cs * o[:, 1] + y
        dx = cs[:, None] * dirs[..., 0] - sn[:, None] * dirs[..., 1]
        dy = sn[:, None] * dirs[..., 0] + cs[:, None] * dirs[..., 1]
        dz = dirs[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = np.where(dx > 1e-9, (a.length - ox[:, None]) / dx,
                          np.where(dx < -1e-9, -ox[:, None] / dx, np.inf))
            ty = np.where(dy > 1e-9, (a.width - oy[:, None]) / dy,
                          np.where(dy < -1e-9, -oy[:, None] / dy, np.inf))
            t_wall = np.minimum(tx, ty)
            t_floor = np.where(dz < -1e-9, -o[:, 2][:, None] / dz, np.inf)
        z_wall = o[:, 2][:, None] + t_wall * dz
        should = (t_floor < t_wall) | (z_wall < a.wall_height - p.wall_top_margin)
        cost = cost + p.miss_weight * outlier * should.sum(axis=1)
        explained = (~should).sum(axis=1).astype(np.float64)
    tilt = np.arccos(np.clip((np.trace(c, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))
    cost = cost + 0.5 * (tilt / p.tilt_sigma) ** 2
    return cost, floor, explained


def _shifted(pose: Pose, c: FloatArray, origin: FloatArray) -> FloatArray:
    """Poses (T, 3) that keep the LIDAR where `pose` has it, under corrections c (T, 3, 3):
    the walls fix the scanner; a changed attitude moves it relative to the chassis."""
    moved = np.einsum("tij,j->ti", c, origin)[:, :2] - origin[:2]  # level frame
    cs, sn = math.cos(pose.yaw), math.sin(pose.yaw)
    out = np.empty((c.shape[0], 3))
    out[:, 0] = pose.x - (cs * moved[:, 0] - sn * moved[:, 1])
    out[:, 1] = pose.y - (sn * moved[:, 0] + cs * moved[:, 1])
    out[:, 2] = pose.yaw
    return out


# ---- refinement ---------------------------------------------------------------------------------


def _correction(roll: float, pitch: float) -> FloatArray:
    return np.asarray(rotation_zyx(roll, pitch, 0.0))


def _roll_pitch(c: FloatArray) -> tuple[float, float]:
    r, p, _ = euler_zyx(tuple(map(tuple, c)))  # type: ignore[arg-type]
    return r, p


@dataclass(frozen=True, eq=False)
class _Priors:
    """What ranks poses besides the scan (same terms as the localizer's)."""

    hint_box: tuple[float, float, float, float] | None
    hint_margin: float
    yaw_prior: float | None
    yaw_sigma: float
    prior: PosePrior | None

    def cost(self, pose: Pose) -> float:
        out = 0.0
        if self.hint_box is not None:
            x0, x1, y0, y1 = self.hint_box
            m = self.hint_margin
            if not (x0 - m <= pose.x <= x1 + m and y0 - m <= pose.y <= y1 + m):
                out += 1e4
        if self.yaw_prior is not None:
            z = math.remainder(pose.yaw - self.yaw_prior, 2.0 * math.pi) / self.yaw_sigma
            out += 0.5 * z * z
        if self.prior is not None:
            d = np.array((pose.x - self.prior.pose.x, pose.y - self.prior.pose.y,
                          math.remainder(pose.yaw - self.prior.pose.yaw, 2.0 * math.pi)))
            out += 0.5 * float(d @ np.linalg.solve(np.asarray(self.prior.cov), d))
        return out


@dataclass(frozen=True, eq=False)
class _Eval:
    """One hypothesis, its pose fitted: the cost (scan + priors) and its evidence."""

    cost: float
    scan_cost: float
    pose: Pose
    c: FloatArray
    floor: int
    explained: int


class _Search:
    """Profile of the model cost over corrections: for each correction the pose is fitted
    to the wall returns (the localizer's 2D refinement), then the 3D cost is taken."""

    def __init__(self, s: _Scan3D, a: ArenaMap, lp: LocalizerParams, p: RelevelParams,
                 priors: _Priors) -> None:
        self.s, self.a, self.lp, self.p, self.priors = s, a, lp, p, priors

    def evaluate(self, c: FloatArray, seed: Pose, seed_c: FloatArray) -> _Eval:
        from ramp.autonomy.perception.localizer import fit_pose

        s, p = self.s, self.p
        start = _shifted(seed, (c @ seed_c.T)[None], seed_c @ s.origin)[0]
        pts = s.echoes @ c.T
        wall = (pts[:, 2] > 0.1) & (pts[:, 2] < self.a.wall_top + p.tau)
        pose = Pose(float(start[0]), float(start[1]), float(start[2]))
        if int(wall.sum()) >= 10:
            pose = fit_pose(pts[wall, :2][::2], pose, self.a, (0.2, 0.1, p.tau), 0.03, 4)
        cost, floor, expl = _model_cost(s, s.echoes, c[None], np.array(pose)[None], self.a, p)
        scan_cost = float(cost[0])
        return _Eval(scan_cost + self.priors.cost(pose), scan_cost, pose, c, int(floor[0]),
                     int(expl[0]))

    def sigma(self, e: _Eval) -> tuple[float, float]:
        """One-sigma uncertainty (rad) of the correction's roll and pitch, from the scan's
        part of the cost's curvature (the prior for level taken out)."""
        d = self.p.sigma_step
        r0, p0 = _roll_pitch(e.c)
        out = []
        for dr, dp in ((d, 0.0), (0.0, d)):
            plus = self.evaluate(_correction(r0 + dr, p0 + dp), e.pose, e.c).cost
            minus = self.evaluate(_correction(r0 - dr, p0 - dp), e.pose, e.c).cost
            k = (plus + minus - 2.0 * e.cost) / (d * d) - 1.0 / self.p.tilt_sigma ** 2
            out.append(1.0 / math.sqrt(k) if k > 0.0 else math.inf)
        return out[0], out[1]

    def polish(self, e: _Eval) -> _Eval:
        """Pattern search in roll and pitch around a hypothesis, halving the step."""
        step = self.p.tilt_step / 2.0
        best = e
        while step >= math.radians(0.2):
            moved = True
            while moved:
                moved = False
                r0, p0 = _roll_pitch(best.c)
                for dr, dp in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                    c = _correction(r0 + dr * step, p0 + dp * step)
                    if _angle_of(c) > self.p.max_tilt + step:
                        continue
                    cand = self.evaluate(c, best.pose, best.c)
                    if cand.cost < best.cost - 1e-6:
                        best, moved = cand, True
            step /= 2.0
        return best


# ---- the search --------------------------------------------------------------------------------


def relevel(record: ScanRecord, *, first: Localization | None = None,
            poses: Sequence[Pose] = (), hint: str | None = None,
            yaw_prior: float | None = None, yaw_sigma: float = YAW_SIGMA,
            prior: PosePrior | None = None, params: LocalizerParams | None = None,
            arena_map: ArenaMap | None = None,
            relevel_params: RelevelParams | None = None) -> Relevel:
    """Find the correction of the record's attitude that best explains the scan.

    Pose candidates come from `poses`, the odometry `prior` and the candidates of a `first`
    localization of the same record (run here when not given). `hint`, `yaw_prior` and
    `prior` rank poses as in `localize`; the tilt found does not depend on which of two
    symmetric poses is right.
    """
    lp = params if params is not None else LocalizerParams()
    a = arena_map if arena_map is not None else ArenaMap()
    p = relevel_params if relevel_params is not None else RelevelParams()
    s = _scan3d(record, lp, a)
    if first is None:
        from ramp.autonomy.perception.localizer import localize

        first = localize(record, hint=hint, yaw_prior=yaw_prior, yaw_sigma=yaw_sigma,
                         prior=prior, relevel=False, params=lp, arena_map=a)
    priors = _Priors(a.hint_box(hint) if hint is not None else None, lp.hint_margin,
                     yaw_prior, yaw_sigma, prior)
    seeds = _pose_seeds(first, poses, prior, priors, p.max_poses)
    if not seeds or s.echoes.shape[0] < lp.min_points:
        return _nothing(record, "no pose to re-level against" if not seeds
                        else "too few returns to re-level")
    search = _Search(s, a, lp, p, priors)
    grid = _grid(p)
    sub = s.echoes[::max(1, p.grid_stride)]
    level = np.eye(3)
    evals: list[_Eval] = []
    for seed in seeds:
        # Coarse: every correction with the pose only moved to keep the LIDAR in place.
        poses_t = _shifted(seed, grid, s.origin)
        cost, _, _ = _model_cost(s, sub, grid, poses_t, a, p)
        picked: list[int] = []
        for k in np.argsort(cost, kind="stable"):
            if all(_angle_between(grid[k], grid[j]) >= p.ambiguity_tilt for j in picked):
                picked.append(int(k))
            if len(picked) >= p.refine_top:
                break
        evals.extend(search.evaluate(grid[k], seed, level) for k in picked)
        evals.append(search.evaluate(level, seed, level))
    evals.sort(key=lambda e: e.cost)
    levels = [e for e in evals if _angle_of(e.c) < 1e-9]
    polished = [search.polish(e) for e in evals[:p.polish_top]]
    best = min(polished, key=lambda e: e.cost)
    # A scan plane tipped the other way about the same horizontal axis projects onto the
    # floor exactly as this one does: only heights (the floor, the walls' top, missing
    # echoes) tell them apart. Try those mirror images explicitly, so an ambiguity shows.
    mirrors = [search.polish(search.evaluate(c, best.pose, best.c))
               for c in _mirrors(best.c, s.lidar)]
    rivals = polished + mirrors + evals[p.polish_top:]
    best = min(rivals, key=lambda e: e.cost)
    # The best the scan can be explained level, whatever the priors say of that pose.
    level_best = min(levels, key=lambda e: e.scan_cost)
    tilt = _angle_of(best.c)
    # The scan itself must be better explained; or, with the scan alone unable to tell (a
    # wrong attitude moves the LIDAR ~0.7 m x sin(error), which a pose can absorb), the
    # scan and the priors together, provided the priors agree with the answer and no level
    # pose explains the scan better (a tilt must not be invented to pull a pose towards a
    # wrong odometry prior or into a wrong start box).
    level_total = min(levels, key=lambda e: e.cost)
    scan_gain = level_best.scan_cost - best.scan_cost
    total_gain = level_total.cost - best.cost
    agrees = priors.cost(best.pose) <= p.prior_agreement
    found = tilt >= p.min_tilt and (
        scan_gain >= p.min_gain
        or (agrees and total_gain >= p.min_gain and scan_gain > -p.min_gain))
    reason = (f"tilted {math.degrees(tilt):.1f} deg: {best.floor} ground returns, "
              f"{best.explained} missing echoes explained, cost {best.cost:.0f} vs "
              f"{level_total.cost:.0f} level")
    if not found:
        reason = (f"no clear tilt (best {math.degrees(tilt):.1f} deg, cost {best.cost:.0f} "
                  f"vs {level_total.cost:.0f} level)")
    else:
        close = [e for e in rivals if _angle_between(e.c, best.c) >= p.ambiguity_tilt
                 and e.cost - best.cost < p.ambiguity_gain]
        if close:
            found = False
            reason = (f"ambiguous tilt: {math.degrees(tilt):.1f} deg and "
                      f"{math.degrees(_angle_of(close[0].c)):.1f} deg (about another axis "
                      "or the other way) explain the scan about as well")
    sigma = search.sigma(best)
    if found and max(sigma) > p.max_sigma:
        found = False
        reason = (f"tilt poorly determined: {math.degrees(tilt):.1f} deg, +-"
                  f"{math.degrees(sigma[0]):.1f} deg in roll, +-{math.degrees(sigma[1]):.1f} "
                  "deg in pitch")
    pose = Pose(best.pose.x, best.pose.y, math.remainder(best.pose.yaw, 2.0 * math.pi))
    return _result(record, best.c, found, reason, pose, best.cost, level_total.cost,
                   best.floor, best.explained, sigma)


def _mirrors(c: FloatArray, lidar: FloatArray) -> list[FloatArray]:
    """Corrections that tip the true scan plane (c @ lidar, LIDAR axes -> level) the other
    way in pitch, in roll, or both, keeping its heading."""
    true = c @ lidar
    roll, pitch, yaw = euler_zyx(tuple(map(tuple, true)))  # type: ignore[arg-type]
    out = []
    for r, p in ((roll, -pitch), (-roll, pitch), (-roll, -pitch)):
        out.append(np.asarray(rotation_zyx(r, p, yaw)) @ lidar.T)
    return out


def _angle_between(c1: FloatArray, c2: FloatArray) -> float:
    return _angle_of(c1.T @ c2)


def _pose_seeds(first: Localization | None, poses: Sequence[Pose], prior: PosePrior | None,
                priors: _Priors, limit: int) -> list[Pose]:
    """Poses to search the tilt from: those the priors like best, and the two the scan fits
    best (a wrong prior must not hide the level explanation)."""
    seeds = list(poses)
    if prior is not None:
        seeds.append(prior.pose)
    fitting: list[Pose] = []
    if first is not None:
        if first.pose is not None:
            seeds.append(first.pose)
        seeds.extend(c.pose for c in first.candidates)
        fitting = [c.pose for c in sorted(first.candidates, key=lambda c: -c.quality)[:2]]
    ranked = _distinct(sorted(seeds, key=priors.cost))
    head = max(1, limit - len(fitting))
    return _distinct(ranked[:head] + fitting + ranked[head:])[:limit]


def _distinct(poses: list[Pose]) -> list[Pose]:
    out: list[Pose] = []
    for s in poses:
        if all(math.hypot(s.x - o.x, s.y - o.y) > 0.1
               or abs(math.remainder(s.yaw - o.yaw, 2 * math.pi)) > math.radians(3)
               for o in out):
            out.append(s)
    return out


def _result(record: ScanRecord, c: FloatArray, found: bool, reason: str, pose: Pose | None,
            cost: float, level_cost: float, floor: int, expl: int,
            sigma: tuple[float, float] = (math.inf, math.inf)) -> Relevel:
    believed = np.asarray(rotation_zyx(record.roll, record.pitch, 0.0))
    true = c @ believed
    roll, pitch, _ = euler_zyx(tuple(map(tuple, true)))  # type: ignore[arg-type]
    lidar = np.asarray(record.lidar_rotation, dtype=np.float64)
    m_b = believed @ lidar  # LIDAR axes -> believed level
    err = m_b.T @ c @ m_b  # the true scanner attitude in its believed axes
    l_roll, l_pitch, _ = euler_zyx(tuple(map(tuple, err)))  # type: ignore[arg-type]
    return Relevel(found, reason, c, _angle_of(c), roll, pitch, roll - record.roll,
                   pitch - record.pitch, l_roll, l_pitch, -l_pitch, pose, cost, level_cost,
                   floor, expl, sigma)


def _nothing(record: ScanRecord, reason: str) -> Relevel:
    return _result(record, np.eye(3), False, reason, None, math.nan, math.nan, 0, 0)


# ---- the quick check ----------------------------------------------------------------------------


def suspect_tilt(record: ScanRecord, pose: Pose | None = None, *, estimate: bool = False,
                 arena_map: ArenaMap | None = None, params: LocalizerParams | None = None,
                 max_no_echo: float = 0.01, crater_depth: float = 0.35,
                 wall_margin: float = 0.05, min_count: int = 5,
                 max_lean: float = math.radians(5.0)) -> TiltCheck:
    """Does the scan contradict the record's attitude? Evidence needing no pose: beams with
    no echo (inside closed walls a level beam always meets something), returns under the
    floor (deeper than a crater) or above the walls' top (`ArenaMap.wall_top`), and an
    attitude the raked floor does not allow (`max_lean`, from vertical; the simulated
    arena's undulations lean MARTE under 1.6 deg 95% of the time, a rock under a wheel
    3-4). With `pose`, only the missing echoes the record's own attitude cannot explain
    count (a chassis rolled on a slope legitimately sends beams over a wall), and with
    `estimate` a `relevel` from that pose is attached."""
    lp = params if params is not None else LocalizerParams()
    a = arena_map if arena_map is not None else ArenaMap()
    s = _scan3d(record, lp, a)
    blocked = record.ranges.size - s.misses.shape[0] - s.echoes.shape[0]  # own frame
    open_beams = max(1, record.ranges.size - blocked)
    misses = s.misses.shape[0]
    if pose is not None and misses:
        _, _, explained = _model_cost(s, s.echoes[:1], np.eye(3)[None],
                                      np.array(pose)[None], a, RelevelParams())
        misses -= int(explained[0])
    no_echo = misses / open_beams
    z = s.echoes[:, 2]
    below = int((z < -crater_depth).sum())
    above = int((z > a.wall_top + wall_margin).sum())
    reasons: list[str] = []
    if no_echo > max_no_echo:
        reasons.append(f"{no_echo * 100:.0f}% of the beams found no echo inside closed walls")
    lean = math.degrees(math.acos(max(-1.0, min(1.0, math.cos(record.roll)
                                               * math.cos(record.pitch)))))
    if lean > math.degrees(max_lean):
        reasons.append(f"the AHRS says the chassis leans {lean:.1f} deg (the raked arena "
                       f"allows {math.degrees(max_lean):.0f})")
    if below >= min_count:
        reasons.append(f"{below} returns under the floor")
    if above >= min_count:
        reasons.append(f"{above} returns above the walls' top")
    found = None
    if pose is not None and estimate:
        found = relevel(record, poses=(pose,), params=lp, arena_map=a)
        if found.found:
            reasons.append(found.reason)
    return TiltCheck(bool(reasons), tuple(reasons), no_echo, below, above, found)
