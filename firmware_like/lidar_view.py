"""What the Hokuyo UTM-30LX-EW sees of the arena: 1081 beams ray-cast in numpy.

Beam i leaves the scanner at angle (i - 540) * 2 pi / 1440 (counter-clockwise positive, 0
straight ahead) in the scanner's own plane. The scanner's pose in the arena is a chain:

    arena <- chassis (x, y, z, Z-Y-X yaw, pitch, roll: `MarteWorld.chassis_pose()`)
          <- mount (the pan/tilt unit's position on the chassis, `LidarParams.mount_*`)
          <- pan (about the mount's z, counter-clockwise positive)
          <- tilt (about the panned y axis, which points left: positive tips the beams DOWN)

Each beam stops at the first of: the four walls (up to their height; a beam over a wall
gets no echo), the terrain (`Terrain.ray_hits`: ground, rock domes, crater bowls), and the
robot's own frame (boxes in the chassis frame, thesis fig. 5.38). Then the sensor's part:
Gaussian range noise (UTM-30LX-EW repeatability), now and then a dust echo short of the
target, ranges outside 0.1-30 m read as "no echo". All of it is vectorised: one scan is a few
dozen numpy operations on 1081-element arrays (see `python -m bench --only arena`).

`range_source(t)` is the SCIP emulator's feed: int millimetres for steps 0..1080, values
below 23 (DMIN) being error codes, as the sensor sends them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from firmware_like.arena_params import (
    HIT_DUST,
    HIT_FRAME,
    HIT_NONE,
    HIT_WALL,
    ArenaParams,
    LidarParams,
)
from firmware_like.marte_params import MarteParams
from firmware_like.terrain import Terrain

if TYPE_CHECKING:
    from firmware_like.marte import MarteWorld

Array = npt.NDArray[np.float64]

_FRAME_QUANTUM = math.radians(0.05)  # gimbal angle resolution for the robot-frame view
_FRAME_CACHE_SIZE = 1024  # gimbal angles remembered (oldest forgotten first)


def rotation_zyx(yaw: float, pitch: float, roll: float) -> Array:
    """Rz(yaw) @ Ry(pitch) @ Rx(roll): body -> world for Z-Y-X Euler angles."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


@dataclass(frozen=True)
class LidarPose:
    """The scanner in the arena: optical centre `origin` (3,) and `rotation` (3, 3) from the
    scanner frame (x along step 540, y left, z up) to the arena frame; and the gimbal's
    `pan` and `tilt` (rad), which alone say where the robot's own structure is in view."""

    origin: Array
    rotation: Array
    pan: float = 0.0
    tilt: float = 0.0


@dataclass(frozen=True)
class Scan:
    """One emulated scan. `ranges` in metres (NaN: no echo), `kinds` what each beam hit
    (`arena_params.HIT_*`), `mm` the values the sensor sends (int millimetres, an error code
    below 23 for no echo), `pose` where it was taken from, `dirs` each beam's unit direction
    in the arena frame."""

    ranges: Array
    kinds: npt.NDArray[np.int8]
    mm: npt.NDArray[np.int64]
    pose: LidarPose
    dirs: Array

    def points(self) -> Array:
        """Hit points (n, 3) in the arena frame; NaN where there was no echo."""
        out: Array = self.pose.origin[None, :] + self.ranges[:, None] * self.dirs
        return out


class LidarView:
    """The LIDAR's view of one arena (walls, terrain, the robot's frame), seeded noise.

    Bind it to a world with `LidarView.of(world, gimbal=...)`: `gimbal()` returns the current
    (pan, tilt) in radians (the servo emulator's true angles); `range_source(t)` then scans
    from the world's current chassis pose. `scan(pose)` scans from any pose, for tests/tools.
    """

    def __init__(self, terrain: Terrain, marte: MarteParams | None = None,
                 arena: ArenaParams | None = None, params: LidarParams | None = None,
                 seed: int = 0) -> None:
        self.terrain = terrain
        self.marte = marte if marte is not None else MarteParams()
        self.arena = arena if arena is not None else terrain.params
        self.params = lp = params if params is not None else LidarParams()
        self._rng = np.random.default_rng(np.random.SeedSequence([seed, 0x11DA2]))
        angles: Array = (np.arange(lp.steps, dtype=np.float64) - lp.front_step) * float(
            lp.step_angle)
        #: Each step's beam angle in radians (0 straight ahead, counter-clockwise positive).
        self.angles = angles
        self._beams = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
        self._mount = np.array([lp.mount_x, lp.mount_y, lp.mount_z])
        self._frame_lo = np.array([[b.x0, b.y0, b.z0] for b in lp.frame]).reshape(-1, 3)
        self._frame_hi = np.array([[b.x1, b.y1, b.z1] for b in lp.frame]).reshape(-1, 3)
        self._frame_corners = np.array([
            [[(b.x0, b.x1)[i], (b.y0, b.y1)[j], (b.z0, b.z1)[k]]
             for i in (0, 1) for j in (0, 1) for k in (0, 1)] for b in lp.frame]).reshape(
            -1, 8, 3)
        self._rock_corners = terrain.rock_boxes()
        self._frame_cache: dict[tuple[int, int], tuple[npt.NDArray[np.intp], Array]] = {}
        self._exact: tuple[tuple[bytes, bytes, float, float], Array, Array,
                           npt.NDArray[np.int8]] | None = None
        self.world: MarteWorld | None = None
        self.gimbal: Callable[[], tuple[float, float]] = lambda: (0.0, 0.0)

    @classmethod
    def of(cls, world: MarteWorld, params: LidarParams | None = None, seed: int | None = None,
           gimbal: Callable[[], tuple[float, float]] | None = None) -> LidarView:
        """A view bound to a live world (its terrain, its chassis pose, its digging dust)."""
        view = cls(world.terrain, world.params, world.arena, params,
                   world.seed if seed is None else seed)
        view.world = world
        if gimbal is not None:
            view.gimbal = gimbal
        return view

    # ---- poses ----------------------------------------------------------------------------

    def pose(self, x: float, y: float, z: float, roll: float, pitch: float, yaw: float,
             pan: float = 0.0, tilt: float = 0.0) -> LidarPose:
        """The scanner's pose for a chassis pose (m, rad) and gimbal angles (rad)."""
        chassis = rotation_zyx(yaw, pitch, roll)
        pan += self.params.mount_yaw  # a mount turned on the chassis turns the whole gimbal
        gimbal = rotation_zyx(pan, tilt, 0.0)
        origin = np.array([x, y, z]) + chassis @ self._mount
        return LidarPose(origin, chassis @ gimbal, pan, tilt)

    def pose_of_world(self, pan: float = 0.0, tilt: float = 0.0) -> LidarPose:
        """The scanner's pose on the bound world's chassis, as it stands now."""
        if self.world is None:
            raise RuntimeError("this view is not bound to a world (use LidarView.of)")
        c = self.world.chassis_pose()
        return self.pose(c.x, c.y, c.z, c.roll, c.pitch, c.yaw, pan, tilt)

    # ---- scans ----------------------------------------------------------------------------

    def range_source(self, t: float) -> npt.NDArray[np.int64]:
        """The SCIP emulator's feed: one scan of the bound world now, as int millimetres for
        steps 0..1080 (values below 23 are error codes: no echo). `t` (the emulator's time)
        is not needed: the world is stepped on the same clock."""
        pan, tilt = self.gimbal()
        digging = bool(self.world.digging) if self.world is not None else False
        return self.scan(self.pose_of_world(pan, tilt), digging=digging).mm

    def scan(self, pose: LidarPose, *, digging: bool = False, noise: bool = True) -> Scan:
        """Cast all 1081 beams from `pose`. `noise` False: exact ranges, no dust (tests)."""
        lp = self.params
        key = (pose.origin.tobytes(), pose.rotation.tobytes(), pose.pan, pose.tilt)
        if self._exact is not None and self._exact[0] == key:
            # The robot and gimbal stand still (digging, dumping, scanning): same geometry.
            _, dirs, t_exact, k_exact = self._exact
        else:
            dirs, t_exact, k_exact = self._cast(pose)
            self._exact = (key, dirs, t_exact, k_exact)
        t, kind = t_exact.copy(), k_exact.copy()
        if noise:
            t += self._rng.standard_normal(t.size) * lp.noise_sigma_near
            far = t > lp.noise_far_from
            if far.any():  # never inside the 7.38 x 3.88 m arena, but other worlds
                t[far] += self._rng.standard_normal(int(far.sum())) * math.sqrt(
                    lp.noise_sigma_far ** 2 - lp.noise_sigma_near ** 2)
            p_dust = lp.dust_probability_digging if digging else lp.dust_probability
            dust = np.nonzero(self._rng.random(t.size) < p_dust)[0]
            if dust.size:
                dust_range = self._rng.uniform(lp.dust_range_min, lp.dust_range_max, dust.size)
                dust, dust_range = dust[dust_range < t[dust]], dust_range[dust_range < t[dust]]
                t[dust] = dust_range
                kind[dust] = HIT_DUST
        valid = (t >= lp.range_min) & (t <= lp.range_max) & (kind != HIT_NONE)
        kind[~valid] = HIT_NONE
        t[~valid] = np.nan
        mm = np.full(t.size, lp.no_return_mm, dtype=np.int64)
        mm[valid] = np.rint(t[valid] * 1000.0)
        return Scan(t, kind, mm, pose, dirs)

    def _cast(self, pose: LidarPose) -> tuple[Array, Array, npt.NDArray[np.int8]]:
        """(beam directions, exact ranges, hit kinds) from `pose`: walls, terrain, frame."""
        dirs = self._beams @ pose.rotation.T
        t, kind = self._walls(pose.origin, dirs)
        rock_rows = self._spans(self._rock_corners, pose.origin, pose.rotation)
        t_ground, k_ground = self.terrain.ray_hits(pose.origin, dirs, t, rock_rows)
        closer = t_ground < t
        t[closer] = t_ground[closer]
        kind[closer] = k_ground[closer]
        rows, t_frame = self._frame(pose)
        if rows.size:
            closer = t_frame < t[rows]
            t[rows[closer]] = t_frame[closer]
            kind[rows[closer]] = HIT_FRAME
        return dirs, t, kind

    def _frame(self, pose: LidarPose) -> tuple[npt.NDArray[np.intp], Array]:
        """(steps, ranges) of the beams that meet the robot's own structure. They depend on
        the gimbal alone: computed for its angles rounded to `_FRAME_QUANTUM` (0.35 mm at
        the posts' 0.4 m) and remembered, since the gimbal keeps to a few angles."""
        key = (round(pose.pan / _FRAME_QUANTUM), round(pose.tilt / _FRAME_QUANTUM))
        found = self._frame_cache.get(key)
        if found is not None:
            return found
        gimbal = rotation_zyx(key[0] * _FRAME_QUANTUM, key[1] * _FRAME_QUANTUM, 0.0)
        rows_out: list[npt.NDArray[np.intp]] = []
        t_out: list[Array] = []
        for i, rows in enumerate(self._spans(self._frame_corners, self._mount, gimbal)):
            if rows.stop <= rows.start:
                continue
            t_box = self._frame_hits(i, self._mount, self._beams[rows] @ gimbal.T)
            hit = np.isfinite(t_box)
            rows_out.append(np.arange(rows.start, rows.stop)[hit])
            t_out.append(t_box[hit])
        steps = np.concatenate(rows_out) if rows_out else np.zeros(0, dtype=np.intp)
        ranges = np.concatenate(t_out) if t_out else np.zeros(0)
        if steps.size and np.unique(steps).size != steps.size:  # boxes behind one another
            order = np.lexsort((ranges, steps))
            steps, ranges = steps[order], ranges[order]
            first = np.ones(steps.size, dtype=bool)
            first[1:] = steps[1:] != steps[:-1]
            steps, ranges = steps[first], ranges[first]
        if len(self._frame_cache) >= _FRAME_CACHE_SIZE:
            self._frame_cache.pop(next(iter(self._frame_cache)))
        self._frame_cache[key] = (steps, ranges)
        return steps, ranges

    def _walls(self, origin: Array, dirs: Array) -> tuple[Array, npt.NDArray[np.int8]]:
        """Distance to the arena's walls along each beam; a beam above a wall's top leaves
        the arena (t stays the distance to the wall, for the terrain's search, kind none)."""
        mp = self.marte
        ox, oy, oz = origin
        dx, dy = dirs[:, 0], dirs[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = np.where(dx > 0, mp.arena_length - ox, ox) / np.abs(dx)
            ty = np.where(dy > 0, mp.arena_width - oy, oy) / np.abs(dy)
        t = np.fmin(tx, ty)
        z = oz + t * dirs[:, 2]
        kind = np.where(z <= self.arena.wall_height, HIT_WALL, HIT_NONE).astype(np.int8)
        return t, kind

    def _spans(self, corners: Array, origin: Array, rotation: Array) -> list[slice]:
        """For each box (corners (m, 8, 3) in the frame of `origin` and `rotation`), the
        steps whose beams can reach it. A beam at angle a reaches only points whose angle
        about the scanner's axis is a, and a convex box spans the interval of its corners'
        angles (all steps when the scanner's axis passes through it or behind it)."""
        if corners.shape[0] == 0:
            return []
        lp = self.params
        local = (corners - origin) @ rotation  # into the scanner frame
        az = np.arctan2(local[..., 1], local[..., 0])
        lo, hi = az.min(axis=1), az.max(axis=1)
        out = []
        for a, b in zip(lo.tolist(), hi.tolist(), strict=True):
            if b - a > math.pi:
                out.append(slice(0, lp.steps))
                continue
            i0 = max(0, math.floor(a / lp.step_angle) + lp.front_step)
            i1 = min(lp.steps, math.ceil(b / lp.step_angle) + lp.front_step + 1)
            out.append(slice(i0, max(i0, i1)))
        return out

    def _frame_hits(self, box: int, origin: Array, dirs: Array) -> Array:
        """Distance to one box of the robot's own structure (chassis frame), slab test."""
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / dirs  # (n, 3), inf where a direction has no component
            t0 = (self._frame_lo[box] - origin) * inv
            t1 = (self._frame_hi[box] - origin) * inv
        # 0 * inf (a beam grazing a box's face) is NaN: treat that face as no constraint.
        lo, hi = np.minimum(t0, t1), np.maximum(t0, t1)
        near = np.where(np.isnan(lo), -np.inf, lo).max(axis=1)
        far = np.where(np.isnan(hi), np.inf, hi).min(axis=1)
        out: Array = np.where((near <= far) & (far > 0.0), np.maximum(near, 0.0), np.inf)
        return out
