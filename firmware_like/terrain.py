"""The arena's ground as a height field: regolith, rocks above it, craters below it.

    height(x, y) = ground(x, y)                      gentle undulation (plane waves)
                 max  rock dome                      half-ellipsoid of the rock's height
                 min  crater bowl                    paraboloid of the crater's depth

A rock or crater sits at the ground's height under its centre (the undulation changes by
under a centimetre across one). Two users, two needs:

- the chassis (`wheel_height`): each wheel is a 0.30 m disc rolling on the surface, so it
  rides up a rock's flank and bridges most of a crater, sinking only as far as the rim lets
  it. Scalar math, evaluated four times per physics step; rocks and craters are only looked
  at when one is within reach of the wheel.
- the LIDAR (`ray_hits`): 1081 rays at once in numpy. The ground is bracketed between its
  lowest and highest possible level, sampled and refined by regula falsi; rocks and crater
  bowls are quadrics, solved in closed form.

numpy is imported on first use: `ramp run --sim` stands MARTE in an empty, level arena with
no LIDAR, whose wheels only ever ask the scalar methods, and numpy would be 19 MB of its
memory for nothing. A terrain with waves, rocks or craters builds its arrays as it is made.
"""

from __future__ import annotations

import importlib
import math
import random
from typing import TYPE_CHECKING, Any

from firmware_like.arena import Layout
from firmware_like.arena_params import HIT_CRATER, HIT_GROUND, HIT_NONE, HIT_ROCK, ArenaParams

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    Array = npt.NDArray[np.float64]
else:
    class _Numpy:
        """numpy, imported the first time one of its names is used here (the module's `np`
        then becomes numpy itself)."""

        def __getattr__(self, name: str) -> Any:
            module = importlib.import_module("numpy")
            globals()["np"] = module
            return getattr(module, name)

    np = _Numpy()

_GROUND_SAMPLES = 8  # samples across the band where a ray can meet the undulating ground
_REFINE_STEPS = 1  # regula falsi steps after the bracket, plus a last interpolation: the
# ground is nearly linear over a bracket (see _regula_falsi), so this is sub-millimetre
_REFINE_STEPS_ROUGH = 6  # on ground far rougher than an arena's (tests, other worlds)
_WHEEL_SAMPLES = 7  # samples along a wheel's contact line when an obstacle is within reach


class Terrain:
    """The height field of one layout; `seed` draws the ground's undulation."""

    def __init__(self, layout: Layout, params: ArenaParams | None = None, seed: int = 0,
                 flat: bool = False) -> None:
        self.layout = layout
        self.params = ap = params if params is not None else ArenaParams()
        rng = random.Random(f"ramp-arena:{seed}:terrain")
        n = 0 if flat or ap.ground_amplitude == 0.0 else ap.ground_waves
        weights = [rng.uniform(0.5, 1.0) for _ in range(n)]
        total = sum(weights) or 1.0
        amp = [ap.ground_amplitude * w / total for w in weights]
        kx, ky, phase = [], [], []
        for _ in range(n):
            direction = rng.uniform(0.0, math.pi)
            k = 2.0 * math.pi / rng.uniform(ap.ground_wavelength_min, ap.ground_wavelength_max)
            kx.append(k * math.cos(direction))
            ky.append(k * math.sin(direction))
            phase.append(rng.uniform(0.0, 2.0 * math.pi))
        self._waves = list(zip(amp, kx, ky, phase, strict=True))
        #: Highest the bare ground rises above (and sinks below) z = 0.
        self.amplitude = 0.0
        #: Steepest slope the bare ground can have (sum of amplitude x wavenumber).
        self._max_slope = 0.0
        #: Sharpest curvature it can have (sum of amplitude x wavenumber squared).
        self._max_curvature = 0.0
        rocks, craters = layout.rocks, layout.craters
        self._rock = [(r.x, r.y, r.radius, r.height, self.ground_at(r.x, r.y)) for r in rocks]
        self._crater = [(c.x, c.y, c.radius, c.depth, self.ground_at(c.x, c.y))
                        for c in craters]
        self._reach = max([r[2] for r in self._rock] + [c[2] for c in self._crater] + [0.0])
        self._centres = [(r[0], r[1]) for r in self._rock] + [(c[0], c[1]) for c in self._crater]
        #: (wheel radius, half width) -> the squared distance `wheel_contact` looks within.
        self._wheel_reach2: dict[tuple[float, float], float] = {}
        self._arrays_built = False
        if n or self._rock or self._crater:  # a level, empty floor needs no numpy
            self._arrays(amp, kx, ky, phase)

    def _arrays(self, amp: list[float] | None = None, kx: list[float] | None = None,
                ky: list[float] | None = None, phase: list[float] | None = None) -> None:
        """The numpy side of the terrain (the rays, the maps), built once: as the terrain is
        made when it has waves, rocks or craters, else on the first call that needs it."""
        if self._arrays_built:
            return
        self._arrays_built = True
        if amp is None or kx is None or ky is None or phase is None:
            amp = [w[0] for w in self._waves]
            kx, ky, phase = ([w[i] for w in self._waves] for i in (1, 2, 3))
        self._amp = np.array(amp)
        self._kx, self._ky, self._phase = np.array(kx), np.array(ky), np.array(phase)
        self.amplitude = float(self._amp.sum())
        self._max_slope = float(np.sum(self._amp * np.hypot(self._kx, self._ky)))
        self._max_curvature = float(np.sum(self._amp * (self._kx ** 2 + self._ky ** 2)))
        self._rx = np.array([r[0] for r in self._rock])
        self._ry = np.array([r[1] for r in self._rock])
        self._rr = np.array([r[2] for r in self._rock])
        self._rh = np.array([r[3] for r in self._rock])
        self._rb = np.array([r[4] for r in self._rock])
        self._cx = np.array([c[0] for c in self._crater])
        self._cy = np.array([c[1] for c in self._crater])
        self._cr = np.array([c[2] for c in self._crater])
        self._cd = np.array([c[3] for c in self._crater])
        self._cb = np.array([c[4] for c in self._crater])
        self._steps = np.arange(4096)  # ray numbers, sliced per call
        self._k = np.stack([self._kx, self._ky])  # (2, waves): phase rate per metre of x, y

    # ---- the surface --------------------------------------------------------------------

    def ground_at(self, x: float, y: float) -> float:
        """Height (m) of the bare regolith at one point, without rocks and craters."""
        z = 0.0
        for amp, kx, ky, phase in self._waves:
            z += amp * math.sin(kx * x + ky * y + phase)
        return z

    def ground(self, x: Array, y: Array) -> Array:
        """Height of the bare regolith at many points (any matching shapes)."""
        self._arrays()
        z = np.zeros(np.broadcast_shapes(np.shape(x), np.shape(y)))
        for amp, kx, ky, phase in self._waves:
            z += amp * np.sin(kx * x + ky * y + phase)
        return z

    def height_at(self, x: float, y: float) -> float:
        """Height of the surface (ground, rock tops, crater bowls) at one point."""
        return self._surface(x, y, self.ground_at(x, y), self._rock, self._crater)

    def height(self, x: Array, y: Array) -> Array:
        """Height of the surface at many points, for maps and tests."""
        self._arrays()
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        z = self.ground(x, y)
        for cx, cy, r, h, base in self._rock:
            q = 1.0 - ((x - cx) ** 2 + (y - cy) ** 2) / (r * r)
            z = np.where(q > 0.0, np.maximum(z, base + h * np.sqrt(np.maximum(q, 0.0))), z)
        for cx, cy, r, depth, base in self._crater:
            q = ((x - cx) ** 2 + (y - cy) ** 2) / (r * r)
            z = np.where(q < 1.0, np.minimum(z, base - depth * (1.0 - q)), z)
        return z

    @staticmethod
    def _surface(x: float, y: float, ground: float,
                 rocks: list[tuple[float, float, float, float, float]],
                 craters: list[tuple[float, float, float, float, float]]) -> float:
        z = ground
        for cx, cy, r, h, base in rocks:
            q = 1.0 - ((x - cx) ** 2 + (y - cy) ** 2) / (r * r)
            if q > 0.0:
                z = max(z, base + h * math.sqrt(q))
        for cx, cy, r, depth, base in craters:
            q = ((x - cx) ** 2 + (y - cy) ** 2) / (r * r)
            if q < 1.0:
                z = min(z, base - depth * (1.0 - q))
        return z

    # ---- wheels -------------------------------------------------------------------------

    @property
    def reach(self) -> float:
        """The largest rock or crater radius (0 with none)."""
        return self._reach

    def clear_of_obstacles(self, x: float, y: float, distance: float) -> bool:
        """True when every rock and crater centre is at least `distance` from (x, y)."""
        d2 = distance * distance
        for cx, cy in self._centres:  # noqa: SIM110 - a loop: all() over a generator is slower
            if (cx - x) ** 2 + (cy - y) ** 2 < d2:
                return False
        return True

    def wheel_contact(self, x: float, y: float, hx: float, hy: float, radius: float,
                      half_width: float) -> tuple[float, float]:
        """(height of the wheel's lowest point, bare ground's height) for a wheel resting on
        the surface, given the wheel's centre (x, y), its rolling direction (hx, hy) (unit),
        its radius and half its width. Over bare ground the two are equal; near a rock or
        crater the wheel rests on the highest place its rim touches (it rides up a rock's
        flank and bridges a crater's bowl, sinking only as far as the rim lets it)."""
        ground = self.ground_at(x, y)
        reach2 = self._wheel_reach2.get((radius, half_width))
        if reach2 is None:
            reach = radius + half_width + self._reach
            reach2 = self._wheel_reach2[(radius, half_width)] = reach ** 2
        rocks = [r for r in self._rock if (r[0] - x) ** 2 + (r[1] - y) ** 2 < reach2]
        craters = [c for c in self._crater if (c[0] - x) ** 2 + (c[1] - y) ** 2 < reach2]
        if not rocks and not craters:
            return ground, ground
        best = -math.inf
        lx, ly = -hy, hx
        for w in (-half_width, 0.0, half_width):  # the tread's two edges and its middle
            px, py = x + w * lx, y + w * ly
            best = max(best, ground + self._rim_support(px, py, hx, hy, radius, craters))
            for i in range(_WHEEL_SAMPLES):
                s = radius * (2.0 * i / (_WHEEL_SAMPLES - 1) - 1.0)
                lift = math.sqrt(max(0.0, radius * radius - s * s)) - radius
                qx, qy = px + s * hx, py + s * hy
                for cx, cy, r, h, base in rocks:
                    q = 1.0 - ((qx - cx) ** 2 + (qy - cy) ** 2) / (r * r)
                    if q > 0.0:
                        best = max(best, base + h * math.sqrt(q) + lift)
                for cx, cy, r, depth, base in craters:
                    q = ((qx - cx) ** 2 + (qy - cy) ** 2) / (r * r)
                    if q < 1.0:
                        best = max(best, base - depth * (1.0 - q) + lift)
        return best, ground

    @staticmethod
    def _rim_support(px: float, py: float, hx: float, hy: float, radius: float,
                     craters: list[tuple[float, float, float, float, float]]) -> float:
        """How far below the ground a wheel's rim line through (px, py) along (hx, hy) rests
        on the ground: 0 unless its lowest point is over a crater, else set by the nearest
        crater edge along the line (-radius: no ground under the wheel at all)."""
        chords: list[tuple[float, float]] = []
        for cx, cy, r, _, _ in craters:
            ex, ey = px - cx, py - cy
            b = ex * hx + ey * hy
            disc = b * b - (ex * ex + ey * ey - r * r)
            if disc > 0.0:
                root = math.sqrt(disc)
                chords.append((-b - root, -b + root))
        if not any(a < 0.0 < b for a, b in chords):
            return 0.0
        ends = [e for chord in chords for e in chord
                if abs(e) <= radius and not any(a < e < b for a, b in chords)]
        if not ends:
            return -radius
        s = min(abs(e) for e in ends)
        return math.sqrt(max(0.0, radius * radius - s * s)) - radius

    def near_obstacle(self, x: float, y: float, reach: float) -> bool:
        """True when some rock or crater disc comes within `reach` of (x, y)."""
        for cx, cy, r, *_ in self._rock + self._crater:
            if (cx - x) ** 2 + (cy - y) ** 2 < (reach + r) ** 2:
                return True
        return False

    # ---- rays ---------------------------------------------------------------------------

    def rock_boxes(self) -> Array:
        """Bounding boxes of the rocks, (m, 8, 3) corners, for a caller that can tell which
        rays may reach them (a scanner sweeps its beams in order of angle)."""
        self._arrays()
        out = np.zeros((len(self._rock), 8, 3))
        for i, (cx, cy, r, h, base) in enumerate(self._rock):
            out[i] = [[cx + sx * r, cy + sy * r, base + sz * h]
                      for sx in (-1, 1) for sy in (-1, 1) for sz in (0, 1)]
        return out

    def ray_hits(self, origin: Array, dirs: Array, t_max: Array,
                 rock_rows: list[slice] | None = None,
                 ) -> tuple[Array, npt.NDArray[np.int8]]:
        """First hit of rays from one `origin` (3,) along unit `dirs` (n, 3) with the surface,
        no farther than `t_max` (n,): (t, kind), t = inf and kind HIT_NONE where none.
        `rock_rows[i]`, when given, holds every ray that can reach rock i."""
        self._arrays()
        n = dirs.shape[0]
        t = np.full(n, np.inf)
        kind = np.full(n, HIT_NONE, dtype=np.int8)
        self._ground_hits(origin, dirs, t_max, t, kind)
        if self._crater:
            self._crater_hits(origin, dirs, t, kind)
        if self._rock:
            rows = rock_rows if rock_rows is not None else [slice(None)] * len(self._rock)
            self._rock_hits(origin, dirs, t_max, rows, t, kind)
        return t, kind

    def _ground_hits(self, origin: Array, dirs: Array, t_max: Array, t: Array,
                     kind: npt.NDArray[np.int8]) -> None:
        """Rays against the bare ground z = sum a sin(k.p + phase). Between z = +amp and
        z = -amp every ray that goes down crosses it. Where the ray descends more steeply
        than the ground can rise, it crosses once: regula falsi on that bracket. A shallower
        ray may touch a wave's crest first: sample the bracket, then refine the first
        crossing."""
        amp = self.amplitude
        oz = float(origin[2])
        dz = dirs[:, 2]
        down = dz < -1e-9
        with np.errstate(divide="ignore"):
            t_top = np.where(down, (oz - amp) / np.where(down, -dz, 1.0), np.inf)
        idx = np.nonzero(down & (t_top <= t_max))[0]
        if idx.size == 0:
            return
        sub_dz = dz[idx]
        if amp == 0.0:
            hit = oz / -sub_dz
            ok = hit <= t_max[idx]
            t[idx[ok]] = hit[ok]
            kind[idx[ok]] = HIT_GROUND
            return
        # Each wave's phase along a ray is alpha + t * beta: precomputed once per scan.
        alpha = self._kx * origin[0] + self._ky * origin[1] + self._phase  # (w,)
        lo = np.maximum(t_top[idx], 0.0)
        hi = np.minimum((oz + amp) / -sub_dz, t_max[idx])
        # Steeper than the ground can rise: -dz > c * horizontal, i.e. dz^2 > c^2 / (1 + c^2)
        # for a unit direction, with a 5 % margin on the steepest slope c.
        c2 = (1.05 * self._max_slope) ** 2
        steep = sub_dz * sub_dz > c2 / (1.0 + c2)
        hit = np.full(idx.size, np.nan)
        for shallow in (False, True):
            rows = np.nonzero(steep != shallow)[0]
            if rows.size == 0:
                continue
            ray = _Rays(oz, alpha, dirs[idx[rows], :2] @ self._k, sub_dz[rows], self._amp)
            if not shallow:
                ta, tb = lo[rows], hi[rows]
                ga, gb = ray.height(ta), ray.height(tb)
                found = np.nonzero(gb <= 0.0)[0]  # else the wall comes first
                if found.size:
                    hit[rows[found]] = self._regula_falsi(ray.subset(found), ta[found],
                                                          tb[found], ga[found], gb[found])
                continue
            frac = np.linspace(0.0, 1.0, _GROUND_SAMPLES)
            ts = lo[rows, None] + (hi - lo)[rows, None] * frac[None, :]
            gs = ray.height_grid(ts)
            below = gs <= 0.0
            sel = np.nonzero(below.any(axis=1))[0]
            if sel.size:
                j = np.argmax(below[sel], axis=1)
                j0 = np.maximum(j - 1, 0)
                hit[rows[sel]] = self._regula_falsi(ray.subset(sel), ts[sel, j0], ts[sel, j],
                                                    gs[sel, j0], gs[sel, j])
        ok = np.isfinite(hit)
        t[idx[ok]] = hit[ok]
        kind[idx[ok]] = HIT_GROUND

    def _regula_falsi(self, ray: _Rays, ta: Array, tb: Array, ga: Array, gb: Array) -> Array:
        """Where each ray meets the ground in [ta, tb] (heights ga >= 0 >= gb). Over a bracket
        this short the ground is nearly linear (its curvature is at most sum a k^2 ~ 0.35 /m:
        a 0.12 m bracket deviates from a line by under a millimetre), so each interpolation
        gains orders of magnitude; rougher ground than the arena's gets more steps."""
        rough = self._max_curvature > 1.0  # /m; the arena's ground stays near 0.35
        for _ in range(_REFINE_STEPS_ROUGH if rough else _REFINE_STEPS):
            with np.errstate(divide="ignore", invalid="ignore"):
                tm = np.where(ga != gb, ta - ga * (tb - ta) / (gb - ga), tb)
            gm = ray.height(tm)
            above = gm > 0.0
            ta, ga = np.where(above, tm, ta), np.where(above, gm, ga)
            tb, gb = np.where(above, tb, tm), np.where(above, gb, gm)
        with np.errstate(divide="ignore", invalid="ignore"):
            out: Array = np.where(ga != gb, ta - ga * (tb - ta) / (gb - ga), tb)
        return out

    def _crater_hits(self, origin: Array, dirs: Array, t: Array,
                     kind: npt.NDArray[np.int8]) -> None:
        """A ray that meets the ground inside a crater's disc goes on into the bowl."""
        rows = np.nonzero(kind == HIT_GROUND)[0]
        if rows.size == 0:
            return
        ox, oy, oz = float(origin[0]), float(origin[1]), float(origin[2])
        tr = t[rows]
        px, py = ox + tr * dirs[rows, 0], oy + tr * dirs[rows, 1]
        ex = px[:, None] - self._cx[None, :]
        ey = py[:, None] - self._cy[None, :]
        inside = ex * ex + ey * ey < (self._cr * self._cr)[None, :]
        if not inside.any():
            return
        r_i, c_i = np.nonzero(inside)
        rows = rows[r_i]
        cx, cy, cr = self._cx[c_i], self._cy[c_i], self._cr[c_i]
        depth, base = self._cd[c_i], self._cb[c_i]
        k = depth / (cr * cr)
        sx, sy, sz = dirs[rows, 0], dirs[rows, 1], dirs[rows, 2]
        ex0, ey0 = ox - cx, oy - cy
        a = k * (sx * sx + sy * sy)
        b = 2.0 * k * (ex0 * sx + ey0 * sy) - sz
        c = k * (ex0 * ex0 + ey0 * ey0) + base - depth - oz
        disc = b * b - 4.0 * a * c
        with np.errstate(divide="ignore", invalid="ignore"):
            far = np.where(a > 1e-12, (-b + np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a),
                           -c / b)
        ok = (disc >= 0.0) & np.isfinite(far) & (far > t[rows])
        t[rows[ok]] = far[ok]
        kind[rows[ok]] = HIT_CRATER

    def _rock_hits(self, origin: Array, dirs: Array, t_max: Array, rock_rows: list[slice],
                   t: Array, kind: npt.NDArray[np.int8]) -> None:
        """Rays against each rock's half-ellipsoid (semi-axes radius, radius, height), all
        (ray, rock) pairs that can meet solved together."""
        ox, oy, oz = float(origin[0]), float(origin[1]), float(origin[2])
        parts = []
        for i, span in enumerate(rock_rows):
            cx, cy, r, h, base = self._rock[i]
            far = math.sqrt((cx - ox) ** 2 + (cy - oy) ** 2) + r
            drop = oz - (base + h)
            if drop > 0.0:
                # From above the rock's top, even the steepest of these rays must fall `drop`
                # before it can touch the rock: if that takes it past the rock, none can.
                steepest = -float(dirs[span, 2].min()) if dirs[span].shape[0] else 0.0
                if steepest <= 0.0 or drop * math.sqrt(1.0 - steepest ** 2) / steepest > far:
                    continue
            # A ray already stopped short of the rock's bounding sphere cannot reach it.
            reach = far - r - math.hypot(r, h)
            cand = self._steps[: t.size][span]
            cand = cand[t[cand] > reach]
            if cand.size:
                parts.append((cand, i))
        if not parts:
            return
        rows = np.concatenate([p[0] for p in parts])
        which = np.concatenate([np.full(p[0].size, p[1]) for p in parts])
        inv_r, inv_h = 1.0 / self._rr[which], 1.0 / self._rh[which]
        base = self._rb[which]
        ex, ey, ez = (ox - self._rx[which]) * inv_r, (oy - self._ry[which]) * inv_r, (
            oz - base) * inv_h
        d = dirs[rows]
        sx, sy, sz = d[:, 0] * inv_r, d[:, 1] * inv_r, d[:, 2] * inv_h
        a = sx * sx + sy * sy + sz * sz
        b = 2.0 * (ex * sx + ey * sy + ez * sz)
        c = ex * ex + ey * ey + ez * ez - 1.0
        disc = b * b - 4.0 * a * c
        near = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
        ok = ((disc >= 0.0) & (near > 0.0) & (oz + near * d[:, 2] >= base - 1e-9)
              & (near <= t_max[rows]))
        if not ok.any():
            return
        rows, near = rows[ok], near[ok]
        best = np.full(t.size, np.inf)
        np.minimum.at(best, rows, near)
        closer = best < t
        t[closer] = best[closer]
        kind[closer] = HIT_ROCK


class _Rays:
    """Rays from one origin over the bare ground, for root finding: each wave's phase along
    ray i is alpha + t * beta[i] (alpha (w,), beta (n, w)), its height dz[i] per metre.

    The waves are summed in float32: its sine is ~10x faster than float64's here, and a
    phase of at most ~40 rad keeps 5e-6 rad, i.e. heights good to 1e-7 m."""

    def __init__(self, oz: float, alpha: Array, beta: Array, dz: Array, amp: Array) -> None:
        self.oz, self.dz = oz, dz
        self.alpha = alpha.astype(np.float32)
        self.beta = beta.astype(np.float32)
        self.amp = amp.astype(np.float32)

    def subset(self, rows: npt.NDArray[np.intp]) -> _Rays:
        out = _Rays.__new__(_Rays)
        out.oz, out.dz, out.alpha, out.amp = self.oz, self.dz[rows], self.alpha, self.amp
        out.beta = self.beta[rows]
        return out

    def height(self, t: Array) -> Array:
        """Height of ray i above the ground at distance t[i]."""
        t32 = t.astype(np.float32)
        ground = np.sin(self.alpha + t32[:, None] * self.beta) @ self.amp
        out: Array = self.oz + t * self.dz - ground
        return out

    def height_grid(self, t: Array) -> Array:
        """Height of ray i above the ground at distances t[i, j]."""
        phase = self.alpha + t.astype(np.float32)[:, :, None] * self.beta[:, None, :]
        out: Array = self.oz + t * self.dz[:, None] - np.sin(phase) @ self.amp
        return out
