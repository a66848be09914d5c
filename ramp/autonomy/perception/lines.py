"""Straight segments in a 2D scan: split-and-merge on the points in beam order.

A wall seen by a planar LIDAR is a run of consecutive beams whose points lie on one line;
what breaks a run is a jump in range (another surface), a missing echo, or a corner. So the
extraction works on the points in the order the beams swept them:

1. **Breakpoints** (Borges & Aldon's adaptive rule): two consecutive points further apart than
   a surface seen at `incidence_min_deg` could put them start a new cluster. A single dust
   echo in front of a wall, or a missing beam, therefore splits the wall, and the merge step
   below joins it again.
2. **Split** (iterative end-point fit): a cluster whose farthest point lies more than
   `split_tol` from the chord between its ends is cut there, recursively. Corners of the
   arena are cut; range noise (a centimetre) is not.
3. **Fit**: each piece gets a total-least-squares line (the principal axis of its points),
   its RMS orthogonal residual, and endpoints projected onto the line.
4. **Merge**: consecutive segments on the same line (normals within `merge_angle_deg`,
   offsets within `merge_dist`, combined RMS within `merge_rms`, gap under `merge_gap`) are
   one surface seen in pieces.
5. **Keep** segments of at least `min_points` points and `min_length` metres: dust, the
   robot's own frame posts and small rocks give short clusters and are dropped here.

Pure numpy, no state, deterministic. Input points are whatever 2D frame the caller works in
(the LIDAR's plane, or the level frame's x, y); `origin` is where the sensor is in that frame,
so ranges and normals are measured from it.

API::

    extract_lines(points, order=None, origin=(0, 0), params=LineParams()) -> list[Segment]
    fit_line(points) -> (normal, rho, rms)

`Segment` fields: `start`, `end` (endpoints, in the order the beams swept them), `normal`
(unit, pointing away from `origin`), `rho` (distance from `origin` to the infinite line),
`rms` (m), `count`, `indices` (rows of `points` it was fitted to), and `length`, `direction`,
`midpoint` as properties.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


@dataclass(frozen=True)
class LineParams:
    """Tuning of the extraction; the defaults suit a UTM-30LX-EW (0.25 deg, 1 cm noise)."""

    beam_step: float = math.radians(0.25)  # angle between two consecutive beams, rad
    range_sigma: float = 0.01  # m, range noise (sets the breakpoint and split margins)
    incidence_min_deg: float = 8.0  # surfaces seen more obliquely than this break up
    split_tol: float = 0.04  # m, plus `split_per_m` per metre of range
    split_per_m: float = 0.004
    merge_angle_deg: float = 3.0
    merge_dist: float = 0.06  # m between the two lines' offsets
    merge_rms: float = 0.03  # m, the merged fit must stay this straight
    merge_gap: float = 1.5  # m, at most this much unseen wall between two pieces
    min_points: int = 8
    min_length: float = 0.25  # m


@dataclass(frozen=True, eq=False)
class Segment:
    """A straight run of scan points and its total-least-squares line."""

    start: tuple[float, float]
    end: tuple[float, float]
    normal: tuple[float, float]  # unit, pointing away from the sensor
    rho: float  # distance from the sensor to the infinite line, m
    rms: float  # RMS orthogonal residual of its points, m
    count: int
    indices: IntArray  # rows of the input points it was fitted to

    @property
    def length(self) -> float:
        return math.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1])

    @property
    def direction(self) -> tuple[float, float]:
        """Unit vector along the line from `start` to `end`."""
        n = self.length
        if n == 0.0:
            return (-self.normal[1], self.normal[0])
        return ((self.end[0] - self.start[0]) / n, (self.end[1] - self.start[1]) / n)

    @property
    def midpoint(self) -> tuple[float, float]:
        return ((self.start[0] + self.end[0]) / 2.0, (self.start[1] + self.end[1]) / 2.0)

    @property
    def normal_angle(self) -> float:
        """Bearing of the normal (rad), i.e. the direction in which the surface faces away."""
        return math.atan2(self.normal[1], self.normal[0])


def fit_line(points: FloatArray, origin: tuple[float, float] = (0.0, 0.0),
             ) -> tuple[tuple[float, float], float, float]:
    """Total-least-squares line through (m, 2) points: (unit normal pointing away from
    `origin`, distance rho from `origin`, RMS orthogonal residual)."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[0] < 2:
        raise ValueError("a line needs at least two points")
    centre = pts.mean(axis=0)
    d = pts - centre
    sxx, syy, sxy = float(d[:, 0] @ d[:, 0]), float(d[:, 1] @ d[:, 1]), float(d[:, 0] @ d[:, 1])
    # The normal is the eigenvector of the smaller eigenvalue of the 2x2 scatter matrix.
    theta = 0.5 * math.atan2(2.0 * sxy, sxx - syy)  # direction of the principal axis
    nx, ny = -math.sin(theta), math.cos(theta)
    rho = nx * (centre[0] - origin[0]) + ny * (centre[1] - origin[1])
    if rho < 0.0:
        nx, ny, rho = -nx, -ny, -rho
    resid = d[:, 0] * nx + d[:, 1] * ny
    rms = float(math.sqrt(float(resid @ resid) / pts.shape[0]))
    return (nx, ny), rho, rms


def extract_lines(points: FloatArray, order: npt.ArrayLike | None = None,
                  origin: tuple[float, float] = (0.0, 0.0),
                  params: LineParams | None = None) -> list[Segment]:
    """Segments of (n, 2) `points` given in beam order. `order` (n,) is each point's beam
    number (so missing beams between two points are known); default 0..n-1."""
    p = params if params is not None else LineParams()
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = pts.shape[0]
    if n < p.min_points:
        return []
    beams = (np.arange(n) if order is None else np.asarray(order)).astype(np.float64)
    rel = pts - np.asarray(origin, dtype=np.float64)
    ranges = np.hypot(rel[:, 0], rel[:, 1])

    clusters = _clusters(pts, ranges, beams, p)
    pieces: list[IntArray] = []
    for rows in clusters:
        pieces.extend(_split(pts, ranges, rows, p))
    segments = [_segment(pts, rows, origin) for rows in pieces if rows.size >= 2]
    segments = _merge(pts, segments, origin, p)
    return [s for s in segments if s.count >= p.min_points and s.length >= p.min_length]


def _clusters(pts: FloatArray, ranges: FloatArray, beams: FloatArray,
              p: LineParams) -> list[IntArray]:
    """Runs of consecutive points with no breakpoint between them."""
    n = pts.shape[0]
    gap = np.hypot(*(pts[1:] - pts[:-1]).T)
    dphi = np.maximum(beams[1:] - beams[:-1], 1.0) * p.beam_step
    lam = math.radians(p.incidence_min_deg)
    with np.errstate(divide="ignore", invalid="ignore"):
        reach = np.minimum(ranges[:-1], ranges[1:]) * np.sin(dphi) / np.sin(
            np.maximum(lam - dphi, 1e-3))
    breaks = np.nonzero(gap > reach + 3.0 * p.range_sigma)[0]
    bounds = np.concatenate(([0], breaks + 1, [n]))
    return [np.arange(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)
            if b - a >= 2]


def _split(pts: FloatArray, ranges: FloatArray, rows: IntArray,
           p: LineParams) -> list[IntArray]:
    """Iterative end-point fit: cut a run at its farthest point from the chord, recursively."""
    out: list[IntArray] = []
    stack = [rows]
    while stack:
        r = stack.pop()
        if r.size < 3:
            out.append(r)
            continue
        a, b = pts[r[0]], pts[r[-1]]
        chord = b - a
        length = math.hypot(chord[0], chord[1])
        if length < 1e-9:
            dist = np.hypot(*(pts[r] - a).T)
        else:
            dist = np.abs((pts[r, 0] - a[0]) * chord[1] - (pts[r, 1] - a[1]) * chord[0]) / length
        k = int(np.argmax(dist))
        tol = p.split_tol + p.split_per_m * float(ranges[r[k]])
        if dist[k] > tol and 0 < k < r.size - 1:
            # Depth-first, left piece on top, so pieces come out in beam order.
            stack.append(r[k:])
            stack.append(r[:k + 1] if k + 1 < r.size - 1 else r[:k])
        else:
            out.append(r)
    # The corner point went to both halves; keep it only where it fits better.
    return _dedupe_corners(pts, out)


def _dedupe_corners(pts: FloatArray, pieces: list[IntArray]) -> list[IntArray]:
    cleaned: list[IntArray] = []
    for piece in pieces:
        if cleaned and cleaned[-1].size and piece.size and cleaned[-1][-1] == piece[0]:
            piece = piece[1:]
        cleaned.append(piece)
    return [c for c in cleaned if c.size]


def _segment(pts: FloatArray, rows: IntArray, origin: tuple[float, float]) -> Segment:
    sub = pts[rows]
    normal, rho, rms = fit_line(sub, origin)
    nx, ny = normal
    # Endpoints: the first and last points projected onto the fitted line.
    ox, oy = origin[0] + nx * rho, origin[1] + ny * rho  # foot of the normal
    tx, ty = -ny, nx
    s0 = (sub[0, 0] - ox) * tx + (sub[0, 1] - oy) * ty
    s1 = (sub[-1, 0] - ox) * tx + (sub[-1, 1] - oy) * ty
    return Segment(start=(ox + s0 * tx, oy + s0 * ty), end=(ox + s1 * tx, oy + s1 * ty),
                   normal=normal, rho=rho, rms=rms, count=int(rows.size), indices=rows)


def _merge(pts: FloatArray, segments: list[Segment], origin: tuple[float, float],
           p: LineParams, look_ahead: int = 3) -> list[Segment]:
    """Join segments that lie on one line: neighbours (a wall cut by dust or a missing
    beam), or two pieces with only nearer things between them (a wall partly hidden by a
    rock or a post)."""
    segs = list(segments)
    changed = True
    while changed:
        changed = False
        for i in range(len(segs)):
            for j in range(i + 1, min(i + 1 + look_ahead, len(segs))):
                between = segs[i + 1:j]
                if not all(_in_front(b, segs[i], origin, p) for b in between):
                    break
                joined = _joined(pts, segs[i], segs[j], origin, p)
                if joined is not None:
                    segs = segs[:i] + [joined] + between + segs[j + 1:]
                    changed = True
                    break
            if changed:
                break
    return segs


def _in_front(seg: Segment, wall: Segment, origin: tuple[float, float],
              p: LineParams) -> bool:
    """Both ends of `seg` are nearer the sensor than `wall`'s line (it is an occluder)."""
    nx, ny = wall.normal
    off = wall.rho - p.merge_dist
    return all(nx * (q[0] - origin[0]) + ny * (q[1] - origin[1]) < off
               for q in (seg.start, seg.end))


def _joined(pts: FloatArray, a: Segment, b: Segment, origin: tuple[float, float],
            p: LineParams) -> Segment | None:
    """`a` and `b` as one segment, when they are on one line; else None."""
    cos_max = math.cos(math.radians(p.merge_angle_deg))
    if a.normal[0] * b.normal[0] + a.normal[1] * b.normal[1] < cos_max:
        return None
    if abs(a.rho - b.rho) > p.merge_dist:
        return None
    if math.hypot(b.start[0] - a.end[0], b.start[1] - a.end[1]) > p.merge_gap:
        return None
    joined = _segment(pts, np.concatenate((a.indices, b.indices)), origin)
    if joined.rms > max(p.merge_rms, a.rms, b.rms):
        return None
    return joined
