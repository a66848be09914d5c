"""Rocks and craters from one 3D scan (thesis 5.3.4 and figure 5.40; SPEC 6.1).

    detection = detect_obstacles(cloud)                 # cloud = cloud.merge(records, x, y, yaw)
    for o in detection.obstacles: o.kind, o.x, o.y, o.d  # "rock" | "crater", metres, arena frame

What the cloud holds: ground, the four walls, the robot's own frame (the BLE posts about 0.4 m
behind the scanner), now and then a dust echo in mid-air, the tops and near faces of rocks,
and craters seen the way a scanner 0.7 m up sees a bowl: beams that cross the near rim fall
into it and end on the far inner wall below the ground, which leaves a shadow with no returns
between the near rim and the far wall. The steps:

1. **Keep what can be ground or obstacle**: drop returns inside the robot's footprint (its
   frame) and far above or below the ground, and those within `wall_margin_m` of each wall
   or beyond it, the wall taken where the cloud shows it (`wall_offsets`: a line through
   the high returns near its map line), since a pose a few cm or a degree off moves it.
   A cluster still taller than any obstacle is dropped later (a wall, a person).
2. **Ground**: a RANSAC plane (the regolith is nearly level; the plane takes up the chassis'
   attitude error and height), then a local correction for the raked ground's undulation
   (+-2 cm over metres): the mean residual of ground-like points over a sliding 0.5 m window
   on a 0.1 m grid, twice, each time dropping points more than 2 cm off. A window that short
   follows waves of 1.5 m to within 4 mm, and the rejection keeps rocks out of it.
3. **Scan by scan levelling**: every scan gets the small roll and pitch that lay its own
   ground returns on the model. The AHRS' attitude and the tilt servo are each a little off
   from scan to scan (0.1 deg is 5 mm at 3 m, as deep as a far crater's wall is seen), and the
   ground itself says by how much. Then the ground is fitted again.
4. **Candidates**: each return's height above the local ground, against a threshold that
   follows the noise the beam's slant gives it (range noise sigma * sin(depression), plus
   the ground model's): above it, rock-like; below it, crater-like. A candidate must belong
   to a run of >= 3 neighbouring beams of one scan lying on one surface: a dust echo is a
   single beam floating in the air, a surface is not.
5. **Clusters**: single linkage (5 cm) over the candidates of each kind, kept when seen in
   >= 2 scans (tilts) with enough points and no point taller than `max_obstacle_height_m`.
6. **Measure**: a rock is a dome (half-ellipsoid, SPEC 6.1: as tall as half its diameter or
   more). An algebraic fit (linear least squares) gives a first dome; it is then refined on
   the ranges themselves (Gauss-Newton, Huber weights): each beam near the rock must end
   where the dome, or the ground beyond it, would stop it. Fitting ranges, not points,
   removes the bias the sensor's along-beam noise puts into point fits (-2 cm on diameters).
   A crater is a bowl (paraboloid): its rim is where each scan's run of beams into it starts
   and ends, on the ground; with the wall returns below the ground, a linear fit of the bowl
   gives centre and diameter, refined the same way on the ranges (a beam whose ground point
   falls inside the rim goes on to the far wall). A run that ends where the next beams
   stopped short on something nearer marks the obstacle `partial` (in a shadow).

Accuracy, from the start region (robot at x = 0.8-0.9 m, y = 1.94 +- 0.15, heading +-3 deg,
`cloud.plan_sweep` lines every 4 cm down to 75 deg, the AHRS 0.3 deg off plus 0.05 deg of
scan-to-scan wobble; tests/unit/test_obstacles.py holds 40 of these layouts, 300 were run):
all 1303 rocks and craters of 15 cm or more found, none confused, no false obstacle;
positions within 1.9 cm, diameters within -2.7..+0.7 cm for rocks and -3.7..+1.7 cm for
craters (mean -0.3 cm), except 11 flagged `partial`, one of which, a crater half hidden
behind a rock, came out 5.4 cm too small. By distance from the scanner, worst position /
diameter error: under 1 m 0.9 / 1.0 cm, 1-2 m 1.9 / 3.7 cm, 2-3 m 1.7 / 2.8 cm, 3-3.5 m
1.5 / 1.8 cm. The cost: ~75 ms of CPU (`python -m bench --only obstacles`).

Limits: only what the sweep saw is found. An obstacle in a rock's shadow, or closer than
the tilt limit lets the scanner look (`SweepPlan.blind_m`), is missed, and one partly
hidden is measured from its visible part (`Obstacle.partial`). The pose given to `merge`
moves every obstacle with it: a pose 5 cm and 2 deg off moves obstacles 3 m out by 12 cm
(walls stay ignored: `wall_offsets` finds them where the cloud has them).

All of it is deterministic (RANSAC draws from a fixed seed) and pure: no clock, no I/O.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ramp.autonomy import arena
from ramp.autonomy.perception.cloud import Cloud, IntArray
from ramp.autonomy.perception.records import FloatArray

BoolArray = npt.NDArray[np.bool_]

# What each point of the cloud was taken for (`Detection.labels`), for plots and tests.
IGNORED = 0  # robot's own frame, walls, beyond the arena, far off the ground band
GROUND = 1
ROCK = 2
CRATER = 3
UNSURE = 4  # above or below the ground, but in no obstacle (noise, dust, too small)
LABEL_NAMES = ("ignored", "ground", "rock", "crater", "unsure")

KINDS = ("rock", "crater")


@dataclass(frozen=True)
class Obstacle:
    """A rock or a crater in the arena frame (SPEC 6.1): centre (x, y) and diameter d in
    metres. `height` is a rock's fitted height or the depth of a crater's deepest return
    (how deep it looked, which is less than its depth when seen from afar); `points` how
    many returns it was measured from; `partial` True when part of it lay in the shadow of
    something nearer the scanner (another rock): it was measured from what showed, and may
    be larger than `d` says. A second scan from elsewhere settles it."""

    kind: str  # "rock" | "crater"
    x: float
    y: float
    d: float
    height: float = 0.0
    points: int = 0
    partial: bool = False

    def as_dict(self) -> dict[str, object]:
        """The fields of `ramp sim perceive --json`'s obstacles (mm resolution)."""
        return {"kind": self.kind, "x": round(self.x, 3), "y": round(self.y, 3),
                "d": round(self.d, 3)}


@dataclass(frozen=True)
class DetectionParams:
    """Every threshold of the detector, each with why it is what it is."""

    # -- what is kept ---------------------------------------------------------------------
    wall_margin_m: float = 0.03  # from each wall: 3 sigma of a wall return (1 cm noise)
    wall_search_m: float = 0.30  # wall returns are looked for this far from the map's line
    wall_min_height_m: float = 0.30  # and this high: above any rock by a wall (SPEC 6.1)
    wall_max_height_m: float = 1.2
    self_margin_m: float = 0.05  # around the footprint (1.2 x 0.75 m): its own frame
    band_m: float = 0.6  # |z| kept: rocks and craters are within 0.3 m of the ground
    max_obstacle_height_m: float = 0.5  # a taller cluster is a wall, a person, not a rock
    # -- ground -------------------------------------------------------------------------
    ransac_band_m: float = 0.03  # plane inliers: undulation +-2 cm plus noise
    ransac_iterations: int = 80
    ransac_sample: int = 3000  # points drawn for scoring (the refit uses all)
    ransac_seed: int = 0
    max_ground_slope: float = 0.2  # rise per metre (11 deg): steeper planes are walls
    cell_m: float = 0.10  # ground grid
    window_cells: int = 2  # half-width of the local mean: 5 x 5 cells = 0.5 m
    min_cell_points: int = 8  # a window with fewer falls back to a 3x wider one, then 0
    ground_band_m: float = 0.04  # first pass: |residual to the plane| below this is ground
    ground_reject_m: float = 0.02  # later passes: |residual to the local model| below this
    level_rounds: int = 2  # scan-by-scan levelling passes (0: trust the records' attitude)
    level_min_points: int = 20  # a scan with fewer ground returns is left as it is
    # -- candidates -----------------------------------------------------------------------
    range_sigma_m: float = 0.01  # UTM-30LX-EW repeatability (SPEC 6.2 sheet)
    ground_sigma_m: float = 0.003  # the ground model's own error (measured: 3-4 mm far)
    sigmas: float = 3.0  # candidate threshold in sigmas of the height noise
    rock_min_m: float = 0.03  # and never below: the ground's texture
    crater_min_m: float = 0.012  # a far crater's wall is seen only 1-3 cm below the ground
    run_gap_m: float = 0.06  # neighbouring beams on one surface are closer than this
    min_run: int = 3  # beams in a run: a dust echo is one beam
    rim_m: float = 0.004  # a beam this far below the ground still falls into a crater
    shadow_m: float = 0.10  # a neighbouring beam this much shorter stopped on something else
    # -- clusters -----------------------------------------------------------------------
    link_m: float = 0.05  # single linkage; SPEC 6.1 obstacles are >= 5 cm apart
    min_points: int = 6
    min_scans: int = 2  # seen at two tilts at least
    min_d_m: float = 0.06  # smaller is texture; SPEC 6.1 rocks are >= 0.10 m
    max_d_m: float = 1.0
    # -- measuring ---------------------------------------------------------------------
    refine: bool = True  # range-based refinement after the algebraic fit
    fit_margin_m: float = 0.06  # beams this far outside the first fit's rim take part
    fit_iterations: int = 10
    max_height_fit_m: float = 0.5  # a fitted rock height or crater depth stays below this


@dataclass(frozen=True, eq=False)
class GroundModel:
    """z = a x + b y + c plus a smooth local correction on a grid (bilinear between cell
    centres; `offsets[iy, ix]` at (x0 + (ix + 0.5) cell, y0 + (iy + 0.5) cell))."""

    plane: tuple[float, float, float]
    x0: float
    y0: float
    cell: float
    offsets: FloatArray

    def height(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """Ground height (m) at arena points (arrays of one shape)."""
        a, b, c = self.plane
        ny, nx = self.offsets.shape
        gx = np.clip((x - self.x0) / self.cell - 0.5, 0.0, max(nx - 1.000001, 0.0))
        gy = np.clip((y - self.y0) / self.cell - 0.5, 0.0, max(ny - 1.000001, 0.0))
        ix, iy = gx.astype(np.intp), gy.astype(np.intp)
        fx, fy = gx - ix, gy - iy
        ix1, iy1 = np.minimum(ix + 1, nx - 1), np.minimum(iy + 1, ny - 1)
        o = self.offsets
        local = ((o[iy, ix] * (1 - fx) + o[iy, ix1] * fx) * (1 - fy)
                 + (o[iy1, ix] * (1 - fx) + o[iy1, ix1] * fx) * fy)
        out: FloatArray = a * x + b * y + c + local
        return out

    def at(self, x: float, y: float) -> float:
        return float(self.height(np.array([x]), np.array([y]))[0])


@dataclass(frozen=True, eq=False)
class Detection:
    """The obstacles found, and what the detector made of each point of the cloud it was
    given: `labels` (n,) one of IGNORED..UNSURE, `heights` (n,) above the ground model (NaN
    where ignored), `cloud` the levelled cloud the heights refer to."""

    obstacles: list[Obstacle]
    ground: GroundModel
    labels: npt.NDArray[np.int8]
    heights: FloatArray
    cloud: Cloud

    def rocks(self) -> list[Obstacle]:
        return [o for o in self.obstacles if o.kind == "rock"]

    def craters(self) -> list[Obstacle]:
        return [o for o in self.obstacles if o.kind == "crater"]


# ---- ground ------------------------------------------------------------------------------


def fit_plane_lsq(points: FloatArray) -> tuple[float, float, float]:
    """(a, b, c) of z = a x + b y + c by plain least squares (the bench's baseline)."""
    a = np.column_stack((points[:, 0], points[:, 1], np.ones(points.shape[0])))
    sol, *_ = np.linalg.lstsq(a, points[:, 2], rcond=None)
    return float(sol[0]), float(sol[1]), float(sol[2])


def fit_plane_ransac(points: FloatArray, band: float = 0.03, iterations: int = 80,
                     sample: int = 3000, seed: int = 0,
                     max_slope: float = 0.2) -> tuple[float, float, float]:
    """(a, b, c) of z = a x + b y + c: the plane through three points with most points
    within `band` (scored on up to `sample` points), no steeper than `max_slope`, then
    refitted by least squares on all its inliers, twice. Deterministic for a seed."""
    if points.shape[0] < 3:
        raise ValueError("a plane needs at least three points")
    rng = np.random.default_rng(seed)
    pts = points if points.shape[0] <= sample else points[
        rng.choice(points.shape[0], sample, replace=False)]
    tri = rng.integers(0, pts.shape[0], size=(iterations, 3))
    p0, p1, p2 = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
    normal = np.cross(p1 - p0, p2 - p0)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = -normal[:, 0] / normal[:, 2]
        b = -normal[:, 1] / normal[:, 2]
    c = p0[:, 2] - a * p0[:, 0] - b * p0[:, 1]
    ok = np.isfinite(a) & np.isfinite(b) & (np.hypot(a, b) < max_slope)
    if not ok.any():
        plane = fit_plane_lsq(points)
    else:
        a, b, c = a[ok], b[ok], c[ok]
        res = pts[None, :, 2] - (a[:, None] * pts[None, :, 0] + b[:, None] * pts[None, :, 1]
                                 + c[:, None])
        best = int(np.argmax((np.abs(res) < band).sum(axis=1)))
        plane = (float(a[best]), float(b[best]), float(c[best]))
    for _ in range(2):
        r = points[:, 2] - (plane[0] * points[:, 0] + plane[1] * points[:, 1] + plane[2])
        inliers = np.abs(r) < band
        if inliers.sum() < 3:
            break
        plane = fit_plane_lsq(points[inliers])
    return plane


def _box_sum(grid: FloatArray, k: int) -> FloatArray:
    """Sum over the (2k+1)^2 window around each cell (zero beyond the edges)."""
    ny, nx = grid.shape
    pad = np.zeros((ny + 2 * k + 1, nx + 2 * k + 1))
    pad[k + 1:k + 1 + ny, k + 1:k + 1 + nx] = grid
    s = pad.cumsum(0).cumsum(1)
    w = 2 * k + 1
    out: FloatArray = s[w:, w:] - s[:-w, w:] - s[w:, :-w] + s[:-w, :-w]
    return out


def fit_ground(points: FloatArray, p: DetectionParams | None = None) -> GroundModel:
    """The ground under a cloud of arena points: RANSAC plane plus the local correction
    (module docstring, step 2)."""
    p = p if p is not None else DetectionParams()
    plane = fit_plane_ransac(points, p.ransac_band_m, p.ransac_iterations, p.ransac_sample,
                             p.ransac_seed, p.max_ground_slope)
    x, y = points[:, 0], points[:, 1]
    res = points[:, 2] - (plane[0] * x + plane[1] * y + plane[2])
    x0 = math.floor(float(x.min()) / p.cell_m) * p.cell_m
    y0 = math.floor(float(y.min()) / p.cell_m) * p.cell_m
    nx = int((float(x.max()) - x0) // p.cell_m) + 1
    ny = int((float(y.max()) - y0) // p.cell_m) + 1
    ix = np.clip(((x - x0) / p.cell_m).astype(np.intp), 0, nx - 1)
    iy = np.clip(((y - y0) / p.cell_m).astype(np.intp), 0, ny - 1)
    flat = iy * nx + ix
    use = np.abs(res) < p.ground_band_m
    model = GroundModel(plane, x0, y0, p.cell_m, np.zeros((ny, nx)))
    k = p.window_cells
    for _ in range(3):
        sums: FloatArray = np.bincount(flat[use], weights=res[use],
                                       minlength=nx * ny).reshape(ny, nx).astype(np.float64)
        cnt: FloatArray = np.bincount(flat[use], minlength=nx * ny).reshape(ny, nx).astype(
            np.float64)
        s1, c1 = _box_sum(sums, k), _box_sum(cnt, k)
        s3, c3 = _box_sum(sums, 3 * k), _box_sum(cnt, 3 * k)
        offsets = np.where(c1 >= p.min_cell_points, s1 / np.maximum(c1, 1.0),
                           np.where(c3 >= p.min_cell_points, s3 / np.maximum(c3, 1.0), 0.0))
        model = GroundModel(plane, x0, y0, p.cell_m, offsets)
        use = np.abs(points[:, 2] - model.height(x, y)) < p.ground_reject_m
    return model


def level_scans(cloud: Cloud, ground: GroundModel, use: BoolArray, band: float,
                min_points: int = 20) -> Cloud:
    """The cloud with each scan turned about its LIDAR centre by the small roll and pitch
    that best lay its ground returns (points of `use` within `band` of the model) on
    `ground` (module docstring, step 3)."""
    pts = cloud.points
    h = pts[:, 2] - ground.height(pts[:, 0], pts[:, 1])
    ok = use & (np.abs(h) < band)
    c, s = math.cos(cloud.pose[2]), math.sin(cloud.pose[2])
    rel = pts - cloud.origins[cloud.scan]
    f = rel[:, 0] * c + rel[:, 1] * s  # ahead of the LIDAR along the robot's heading
    lat = -rel[:, 0] * s + rel[:, 1] * c  # to its left
    m = cloud.origins.shape[0]
    sc, fo, lo, ho = cloud.scan[ok], f[ok], lat[ok], h[ok]

    def total(w: FloatArray) -> FloatArray:
        out: FloatArray = np.bincount(sc, weights=w, minlength=m).astype(np.float64)
        return out

    ff, fl, ll = total(fo * fo), total(fo * lo), total(lo * lo)
    fh, lh = total(fo * ho), total(lo * ho)
    ridge = 1e-3 * (ff + ll) + 1e-9  # a far line is nearly all one f: keep it solvable
    det = (ff + ridge) * (ll + ridge) - fl * fl
    slope_f = ((ll + ridge) * fh - fl * lh) / det  # h ~ slope_f * f + slope_l * lat
    slope_l = ((ff + ridge) * lh - fl * fh) / det
    enough = np.bincount(sc, minlength=m) >= min_points
    slope_f = np.where(enough, slope_f, 0.0)[cloud.scan]
    slope_l = np.where(enough, slope_l, 0.0)[cloud.scan]
    new = pts.copy()
    new[:, 2] -= slope_f * f + slope_l * lat
    # The same turn moves a point below the LIDAR along the slope, by as much (first order).
    dz = rel[:, 2]
    new[:, 0] += dz * (slope_f * c - slope_l * s)
    new[:, 1] += dz * (slope_f * s + slope_l * c)
    return dataclasses.replace(cloud, points=new)


# ---- candidates and clusters -------------------------------------------------------------


def _runs(cand: BoolArray, cloud: Cloud, gap: float, min_run: int) -> BoolArray:
    """Candidates in a run of >= `min_run` neighbouring beams of one scan (a skipped beam
    allowed) whose points follow one another within `gap`."""
    idx = np.nonzero(cand)[0]
    if idx.size == 0:
        return cand.copy()
    scan, beam, pts = cloud.scan[idx], cloud.beam[idx], cloud.points[idx]
    joined = np.zeros(idx.size, dtype=bool)
    joined[1:] = ((scan[1:] == scan[:-1]) & (beam[1:] - beam[:-1] <= 2)
                  & (np.linalg.norm(pts[1:] - pts[:-1], axis=1) < gap))
    run = np.cumsum(~joined)
    out = np.zeros_like(cand)
    out[idx[np.bincount(run)[run] >= min_run]] = True
    return out


def clusters(xy: FloatArray, link: float) -> list[IntArray]:
    """Single-linkage groups of 2D points (indices into `xy`), joined when closer than
    `link`: candidate pairs from a grid of `link` cells, then label propagation with
    pointer jumping."""
    n = xy.shape[0]
    if n == 0:
        return []
    key = np.floor(xy / link).astype(np.int64)
    key -= key.min(axis=0)
    width = int(key[:, 1].max()) + 3
    code = key[:, 0] * width + key[:, 1] + 1
    order = np.argsort(code, kind="stable")
    sorted_code = code[order]
    firsts: list[IntArray] = []
    seconds: list[IntArray] = []
    for dx, dy in ((0, 0), (0, 1), (1, -1), (1, 0), (1, 1)):
        target = code + dx * width + dy
        lo = np.searchsorted(sorted_code, target, "left")
        counts = np.searchsorted(sorted_code, target, "right") - lo
        total = int(counts.sum())
        if total == 0:
            continue
        a = np.repeat(np.arange(n), counts)
        b = order[np.repeat(lo, counts) + np.arange(total) - np.repeat(
            np.cumsum(counts) - counts, counts)]
        close = np.sum((xy[a] - xy[b]) ** 2, axis=1) < link * link
        firsts.append(a[close])
        seconds.append(b[close])
    a, b = np.concatenate(firsts), np.concatenate(seconds)
    label = np.arange(n)
    while True:
        low = np.minimum(label[a], label[b])
        new = label.copy()
        np.minimum.at(new, a, low)
        np.minimum.at(new, b, low)
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    _, lab = np.unique(label, return_inverse=True)
    lab = lab.reshape(-1)
    order = np.argsort(lab, kind="stable")
    bounds = np.searchsorted(lab[order], np.arange(int(lab.max()) + 2))
    return [order[bounds[i]:bounds[i + 1]] for i in range(int(lab.max()) + 1)]


# ---- measuring ---------------------------------------------------------------------------


def _ground_hit(cloud: Cloud, ground: GroundModel, idx: IntArray) -> FloatArray:
    """Where the beams of points `idx` would meet the ground model (the plane, then three
    fixed-point steps on the smooth local part)."""
    o = cloud.origins[cloud.scan[idx]]
    u = cloud.points[idx] - o
    u /= np.linalg.norm(u, axis=1)[:, None]
    down = np.minimum(u[:, 2], -1e-6)
    a, b, c = ground.plane
    t = (o[:, 2] - (a * o[:, 0] + b * o[:, 1] + c)) / (-down + a * u[:, 0] + b * u[:, 1])
    for _ in range(3):
        q = o + t[:, None] * u
        t = t + (q[:, 2] - ground.height(q[:, 0], q[:, 1])) / -down
    out: FloatArray = o + t[:, None] * u
    return out


def _dome_fit(x: FloatArray, y: FloatArray, h: FloatArray,
              ) -> tuple[float, float, float, float] | None:
    """(cx, cy, r, height) of the half-ellipsoid (x-cx)^2 + (y-cy)^2 + (r/height)^2 h^2 =
    r^2 through points at heights h above the ground: linear in (cx, cy, C, K)."""
    mx, my = float(x.mean()), float(y.mean())
    u, v = x - mx, y - my
    a = np.column_stack((2 * u, 2 * v, np.ones_like(u), -h * h))
    sol, *_ = np.linalg.lstsq(a, u * u + v * v, rcond=None)
    cx, cy, c0, k = (float(s) for s in sol)
    r2 = c0 + cx * cx + cy * cy
    if r2 <= 0.0 or k <= 0.0:
        return None
    r = math.sqrt(r2)
    return mx + cx, my + cy, r, r / math.sqrt(k)


def _bowl_fit(rim: FloatArray, wall: FloatArray) -> tuple[float, float, float, float] | None:
    """(cx, cy, r, depth) of the paraboloid rho^2 = r^2 (1 + h / depth) through rim points
    (x, y) at the ground's level and wall points (x, y, h < 0): linear in (cx, cy, C, K)."""
    xy = np.concatenate((rim[:, :2], wall[:, :2]))
    h = np.concatenate((np.zeros(rim.shape[0]), wall[:, 2]))
    if xy.shape[0] < 4:
        return None
    mx, my = float(xy[:, 0].mean()), float(xy[:, 1].mean())
    u, v = xy[:, 0] - mx, xy[:, 1] - my
    a = np.column_stack((2 * u, 2 * v, np.ones_like(u), h))
    sol, *_ = np.linalg.lstsq(a, u * u + v * v, rcond=None)
    cx, cy, c0, k = (float(s) for s in sol)
    r2 = c0 + cx * cx + cy * cy
    if r2 <= 0.0:
        return None
    depth = r2 / k if k > 1e-9 else float(-h.min()) if h.size else 0.1
    return mx + cx, my + cy, math.sqrt(r2), max(depth, 0.02)


def _dome_ranges(theta: FloatArray, base: float, o: FloatArray, u: FloatArray,
                 t_ground: FloatArray) -> FloatArray:
    """Range along each beam (origins o, unit directions u) to the dome theta = (cx, cy,
    r, height) standing at height `base`, or to the ground (`t_ground`) when it misses."""
    cx, cy, r, hh = theta
    sx, sy, sz = u[:, 0] / r, u[:, 1] / r, u[:, 2] / hh
    ex, ey, ez = (o[:, 0] - cx) / r, (o[:, 1] - cy) / r, (o[:, 2] - base) / hh
    a = sx * sx + sy * sy + sz * sz
    b = 2.0 * (ex * sx + ey * sy + ez * sz)
    c = ex * ex + ey * ey + ez * ez - 1.0
    disc = b * b - 4.0 * a * c
    t = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
    hit = (disc > 0.0) & (t > 0.0) & (o[:, 2] + t * u[:, 2] >= base) & (t < t_ground)
    out: FloatArray = np.where(hit, t, t_ground)
    return out


def _bowl_ranges(theta: FloatArray, base: float, o: FloatArray, u: FloatArray,
                 t_ground: FloatArray) -> FloatArray:
    """Range along each beam to the ground, or, when its ground point falls inside the
    bowl theta = (cx, cy, r, depth) at height `base`, on to the bowl's far wall."""
    cx, cy, r, depth = theta
    gx, gy = o[:, 0] + t_ground * u[:, 0] - cx, o[:, 1] + t_ground * u[:, 1] - cy
    inside = gx * gx + gy * gy < r * r
    k = depth / (r * r)
    ex, ey = o[:, 0] - cx, o[:, 1] - cy
    a = k * (u[:, 0] ** 2 + u[:, 1] ** 2)
    b = 2.0 * k * (ex * u[:, 0] + ey * u[:, 1]) - u[:, 2]
    c = k * (ex * ex + ey * ey) + base - depth - o[:, 2]
    disc = b * b - 4.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        far = (-b + np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
    ok = inside & (disc >= 0.0) & np.isfinite(far) & (far > t_ground)
    out: FloatArray = np.where(ok, far, t_ground)
    return out


def _refine(model: str, cloud: Cloud, ground: GroundModel, keep: BoolArray,
            first: tuple[float, float, float, float], p: DetectionParams,
            ) -> tuple[float, float, float, float]:
    """Gauss-Newton with Huber weights on the ranges of the beams near an obstacle:
    measured range against the range to the dome/bowl `first` = (cx, cy, r, height)
    standing on the ground model, or to the ground where the beam misses it."""
    cx, cy, r, _ = first
    pts = cloud.points
    near = keep & (np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) < r + p.fit_margin_m)
    idx = np.nonzero(near)[0]
    if idx.size < 8:
        return first
    o = cloud.origins[cloud.scan[idx]]
    meas = np.linalg.norm(pts[idx] - o, axis=1)
    u = (pts[idx] - o) / meas[:, None]
    t_ground = np.linalg.norm(_ground_hit(cloud, ground, idx) - o, axis=1)
    ranges = _dome_ranges if model == "rock" else _bowl_ranges
    theta = np.clip(np.array(first, dtype=np.float64), 0.01, None)
    theta[3] = min(theta[3], p.max_height_fit_m)
    huber = 2.0 * p.range_sigma_m
    step_size = 1e-3
    for _ in range(p.fit_iterations):
        base = ground.at(float(theta[0]), float(theta[1]))
        now = ranges(theta, base, o, u, t_ground)
        res = meas - now
        w = np.where(np.abs(res) <= huber, 1.0, huber / np.maximum(np.abs(res), 1e-12))
        jac = np.empty((idx.size, 4))
        for k in range(4):
            moved = theta.copy()
            moved[k] += step_size
            jac[:, k] = (ranges(moved, base, o, u, t_ground) - now) / step_size
        sw = np.sqrt(w)
        jw, rw = jac * sw[:, None], res * sw
        lhs = jw.T @ jw
        lhs += 1e-3 * np.diag(np.diag(lhs)) + 1e-9 * np.eye(4)
        step = np.linalg.solve(lhs, jw.T @ rw)
        step = np.clip(step, -0.05, 0.05)  # a fit that wanders off is not trusted further
        theta = theta + step
        theta[2:] = np.clip(theta[2:], 0.01, p.max_height_fit_m)
        if float(np.max(np.abs(step))) < 2e-4:
            break
    if math.hypot(theta[0] - cx, theta[1] - cy) > max(r, 0.05) or not (
            0.5 * r <= theta[2] <= 2.0 * r):
        return first  # the refinement disagrees wildly with the data's own shape
    return float(theta[0]), float(theta[1]), float(theta[2]), float(theta[3])


class _Beams:
    """Finds the point of (scan, beam) in a merged cloud: `merge` keeps scans and beams in
    ascending order, so one sorted key does it."""

    def __init__(self, cloud: Cloud) -> None:
        self.stride = int(cloud.beam.max()) + 2 if len(cloud) else 1
        self.key = cloud.scan * self.stride + cloud.beam

    def find(self, scan: int, beam: int) -> int:
        """Index of that point, -1 when the beam gave no return."""
        want = scan * self.stride + beam
        j = int(np.searchsorted(self.key, want))
        return j if j < self.key.size and self.key[j] == want else -1


def _occluded(cloud: Cloud, beams: _Beams, scan: int, beam: int, step: int, reach: float,
              p: DetectionParams) -> bool:
    """True when the next two beams beyond `beam` (going `step`) both stopped well short of
    `reach`: something stands nearer the scanner there (one short beam is a dust echo)."""
    o = cloud.origins[scan]
    for k in (1, 2):
        j = beams.find(scan, beam + k * step)
        if j < 0 or float(np.linalg.norm(cloud.points[j] - o)) >= reach - p.shadow_m:
            return False
    return True


def _shadow_edges(cloud: Cloud, beams: _Beams, group: IntArray, p: DetectionParams) -> int:
    """How many of a rock cluster's runs end in the shadow of something nearer the
    scanner."""
    ranges = np.linalg.norm(cloud.points[group] - cloud.origins[cloud.scan[group]], axis=1)
    edges = 0
    for s in np.unique(cloud.scan[group]):
        in_scan = cloud.scan[group] == s
        b, far = cloud.beam[group[in_scan]], ranges[in_scan]
        for end, step in ((int(np.argmin(b)), -1), (int(np.argmax(b)), 1)):
            edges += _occluded(cloud, beams, int(s), int(b[end]), step, float(far[end]), p)
    return edges


def _crater_evidence(cloud: Cloud, beams: _Beams, ground: GroundModel, h: FloatArray,
                     group: IntArray, p: DetectionParams) -> tuple[FloatArray, FloatArray, int]:
    """Rim points (where each scan's run of beams into the crater starts and ends, on the
    ground), wall points (x, y, h) and the number of shadow edges of one crater cluster.
    Each run is first widened to the neighbouring beams that still end (slightly) below
    the ground. A run that ends where the next beam stopped short on something standing in
    front (a rock's shadow covers part of the crater) gives no rim point there."""
    rim: list[FloatArray] = []
    wall: list[int] = []
    shadow = 0
    for s in np.unique(cloud.scan[group]):
        run = cloud.beam[group[cloud.scan[group] == s]]
        for end, step in ((int(run.min()), -1), (int(run.max()), 1)):
            last = beams.find(int(s), end)
            while True:
                j = beams.find(int(s), int(cloud.beam[last]) + step)
                if j < 0 or not h[j] < -p.rim_m:
                    break
                wall.append(j)
                last = j
            inside = _ground_hit(cloud, ground, np.array([last]))[0]
            out = beams.find(int(s), int(cloud.beam[last]) + step)
            reach = float(np.linalg.norm(inside - cloud.origins[int(s)]))
            if out >= 0 and abs(h[out]) < 3.0 * p.rim_m:
                rim.append(0.5 * (inside + cloud.points[out]))  # the rim lies between
            elif _occluded(cloud, beams, int(s), int(cloud.beam[last]), step, reach, p):
                shadow += 1  # the next beams stopped on something in front
            else:
                rim.append(inside)
    w = np.unique(np.concatenate((group, np.asarray(wall, dtype=np.intp))))
    wall_pts = np.column_stack((cloud.points[w, :2], np.minimum(h[w], 0.0)))
    return np.asarray(rim).reshape(-1, 3), wall_pts, shadow


# ---- the detector ------------------------------------------------------------------------


#: The four walls as (point on the wall, unit normal into the arena), SPEC 6.1.
WALLS: tuple[tuple[tuple[float, float], tuple[float, float]], ...] = (
    ((0.0, 0.0), (1.0, 0.0)),  # x = 0, behind the collector
    ((arena.ARENA_LENGTH_M, 0.0), (-1.0, 0.0)),  # the far wall
    ((0.0, 0.0), (0.0, 1.0)),  # y = 0, on the right facing +x
    ((0.0, arena.ARENA_WIDTH_M), (0.0, -1.0)),  # y = 3.88, on the left
)
#: Each wall's length from its point in `WALLS`, along it (the arena's width, then length).
WALL_LENGTHS = (arena.ARENA_WIDTH_M, arena.ARENA_WIDTH_M, arena.ARENA_LENGTH_M,
                arena.ARENA_LENGTH_M)


def wall_offsets(cloud: Cloud, p: DetectionParams) -> list[tuple[float, float] | None]:
    """Where each wall really is in the cloud, as (offset, slope): the wall returns (high
    points near the wall's expected line) lie at `offset + slope * s` from it (into the
    arena), s running along the wall from its origin. A pose a few cm or a degree off puts
    the walls there instead of on their map lines; None where the sweep saw too little."""
    pts = cloud.points
    out: list[tuple[float, float] | None] = []
    high = (pts[:, 2] - cloud.ground_z > p.wall_min_height_m) & (
        pts[:, 2] - cloud.ground_z < p.wall_max_height_m)
    for ((ox, oy), (nx, ny)), length in zip(WALLS, WALL_LENGTHS, strict=True):
        dist = (pts[:, 0] - ox) * nx + (pts[:, 1] - oy) * ny
        along = -(pts[:, 0] - ox) * ny + (pts[:, 1] - oy) * nx
        # Not where the next wall runs through the search band: its returns, a line across
        # this one, would tilt the fit (a corner's returns once made the x = 0 wall cross
        # the arena diagonally, and every rock beyond it was dropped as behind the wall).
        ends = ((along > p.wall_search_m + p.wall_margin_m)
                & (along < length - p.wall_search_m - p.wall_margin_m))
        sel = high & (np.abs(dist) < p.wall_search_m) & ends
        if int(sel.sum()) < 20:
            out.append(None)
            continue
        s_, d_ = along[sel], dist[sel]
        keep = np.ones(s_.size, dtype=bool)
        fit = (float(np.median(d_)), 0.0)
        for _ in range(3):
            if int(keep.sum()) < 20:
                break
            a = np.column_stack((np.ones(int(keep.sum())), s_[keep]))
            sol, *_ = np.linalg.lstsq(a, d_[keep], rcond=None)
            fit = (float(sol[0]), float(sol[1]))
            keep = np.abs(d_ - (fit[0] + fit[1] * s_)) < 0.03
        # A pose a few cm and a degree or two off moves a wall that much; a line further
        # off than the search band anywhere along the wall is not the wall.
        if max(abs(fit[0]), abs(fit[0] + fit[1] * length)) > p.wall_search_m:
            out.append(None)
            continue
        out.append(fit)
    return out


def kept_points(cloud: Cloud, p: DetectionParams) -> BoolArray:
    """Points that can be ground or obstacle: outside the robot's footprint (and margin),
    more than `wall_margin_m` inside each wall where the cloud shows it (`wall_offsets`, or
    its map line), within `band_m` of the footprint's height (module step 1)."""
    pts = cloud.points
    rx, ry, yaw = cloud.pose
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = pts[:, 0] - rx, pts[:, 1] - ry
    own = (np.abs(dx * c + dy * s) < arena.ROBOT_LENGTH_M / 2 + p.self_margin_m) & (
        np.abs(-dx * s + dy * c) < arena.ROBOT_WIDTH_M / 2 + p.self_margin_m)
    inside = np.ones(pts.shape[0], dtype=bool)
    for ((ox, oy), (nx, ny)), seen in zip(WALLS, wall_offsets(cloud, p), strict=True):
        dist = (pts[:, 0] - ox) * nx + (pts[:, 1] - oy) * ny
        wall: FloatArray | float = 0.0
        if seen is not None:
            along = -(pts[:, 0] - ox) * ny + (pts[:, 1] - oy) * nx
            wall = np.maximum(seen[0] + seen[1] * along, 0.0)  # never outside the map's
        inside &= dist > wall + p.wall_margin_m
    out: BoolArray = inside & ~own & (np.abs(pts[:, 2] - cloud.ground_z) < p.band_m)
    return out


def in_obstacle_region(x: float) -> bool:
    """SPEC 6.1's obstacle region: 1.5 <= x < 4.44."""
    return arena.START_END_X_M <= x < arena.OBSTACLE_END_X_M


def detect_obstacles(cloud: Cloud, params: DetectionParams | None = None, *,
                     obstacle_region_only: bool = False) -> Detection:
    """Rocks and craters in one merged 3D scan (see the module docstring for the steps).
    Obstacles are reported with their centre inside the arena; with
    `obstacle_region_only`, inside SPEC 6.1's obstacle region (1.5 <= x < 4.44) only."""
    p = params if params is not None else DetectionParams()
    n = len(cloud)
    labels = np.zeros(n, dtype=np.int8)
    keep = kept_points(cloud, p)
    if int(keep.sum()) < 3:
        empty = GroundModel((0.0, 0.0, cloud.ground_z), 0.0, 0.0, p.cell_m, np.zeros((1, 1)))
        return Detection([], empty, labels, np.full(n, np.nan), cloud)
    for _ in range(p.level_rounds):
        rough = fit_ground(cloud.points[keep], p)
        cloud = level_scans(cloud, rough, keep, p.ground_band_m, p.level_min_points)
    pts = cloud.points
    ground = fit_ground(pts[keep], p)
    h = np.full(n, np.nan)
    h[keep] = pts[keep, 2] - ground.height(pts[keep, 0], pts[keep, 1])
    labels[keep] = GROUND
    slant = np.abs(cloud.directions()[:, 2])
    sigma = np.hypot(p.range_sigma_m * slant, p.ground_sigma_m) * p.sigmas
    hk = np.where(keep, h, 0.0)
    candidates = {
        "rock": _runs(keep & (hk > np.maximum(p.rock_min_m, sigma)), cloud, p.run_gap_m,
                      p.min_run),
        "crater": _runs(keep & (hk < -np.maximum(p.crater_min_m, sigma)), cloud,
                        p.run_gap_m, p.min_run),
    }
    found: list[tuple[Obstacle, IntArray]] = []
    beams = _Beams(cloud)
    for kind in KINDS:
        idx = np.nonzero(candidates[kind])[0]
        labels[idx] = UNSURE
        for group in clusters(pts[idx, :2], p.link_m):
            g = idx[group]
            if g.size < p.min_points or np.unique(cloud.scan[g]).size < p.min_scans:
                continue
            if float(np.abs(h[g]).max()) > p.max_obstacle_height_m:
                continue  # a wall that slipped through, or something standing there
            obstacle = _measure(kind, cloud, beams, ground, keep, h, g, p)
            if obstacle is not None:
                found.append((obstacle, g))
    obstacles: list[Obstacle] = []
    for obstacle, g in sorted(found, key=lambda item: -item[0].points):
        if any(o.kind == obstacle.kind and math.hypot(o.x - obstacle.x, o.y - obstacle.y)
               < o.d / 2 for o in obstacles):
            continue  # a fragment of one already measured
        if not (0.0 <= obstacle.x <= arena.ARENA_LENGTH_M
                and 0.0 <= obstacle.y <= arena.ARENA_WIDTH_M):
            continue
        if obstacle_region_only and not in_obstacle_region(obstacle.x):
            continue
        labels[g] = ROCK if obstacle.kind == "rock" else CRATER
        obstacles.append(obstacle)
    obstacles.sort(key=lambda o: (o.kind, o.x, o.y))
    return Detection(obstacles, ground, labels, h, cloud)


def _measure(kind: str, cloud: Cloud, beams: _Beams, ground: GroundModel, keep: BoolArray,
             h: FloatArray, g: IntArray, p: DetectionParams) -> Obstacle | None:
    """Centre, diameter and height of one cluster (module docstring, step 6)."""
    pts = cloud.points
    first: tuple[float, float, float, float] | None
    if kind == "rock":
        first = _dome_fit(pts[g, 0], pts[g, 1], h[g])
        shadow = _shadow_edges(cloud, beams, g, p)
    else:
        rim, wall, shadow = _crater_evidence(cloud, beams, ground, h, g, p)
        first = _bowl_fit(rim, wall)
    if first is None or not math.isfinite(sum(first)):
        return None
    fit = _refine(kind, cloud, ground, keep, first, p) if p.refine else first
    cx, cy, r, height = fit
    if not p.min_d_m <= 2.0 * r <= p.max_d_m:
        return None
    if kind == "crater":
        height = float(-h[g].min())
    return Obstacle(kind, cx, cy, 2.0 * r, height, int(g.size), partial=shadow > 0)
