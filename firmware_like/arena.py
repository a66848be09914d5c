"""The RMC arena's layout (SPEC 6.1): start boxes, rocks, craters, and the geometry the
referee and the physics share.

Frame (SPEC 6.1): x along the arena, 0 at the wall the collector stands behind, 7.38 m at the
far wall; y across, 0..3.88 m, +y on the LEFT when facing +x; z up; yaw counter-clockwise from
+x (degrees in files and on command lines, radians in code). A robot pose is the centre of its
footprint and its heading.

A `Layout` is what the judges set before a run: the obstacles and the start box and heading.
It comes from a seed (`random_layout`, under the SPEC's rules) or from a world file
(`firmware_like.world_file`). The exact start pose is the box's pose perturbed by the seed
(`start_pose`), unless the world file pins it.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import NamedTuple

from firmware_like.arena_params import ArenaParams
from firmware_like.marte_params import MarteParams

START_BOXES = ("left", "right")
HEADINGS_DEG = (0, 90, 180, 270)


@dataclass(frozen=True)
class Rock:
    """A rock: a dome of `height` on a disc of diameter `d` centred on (x, y)."""

    x: float
    y: float
    d: float
    height: float

    @property
    def radius(self) -> float:
        return self.d / 2.0


@dataclass(frozen=True)
class Crater:
    """A crater: a bowl `depth` deep under a disc of diameter `d` centred on (x, y)."""

    x: float
    y: float
    d: float
    depth: float

    @property
    def radius(self) -> float:
        return self.d / 2.0


@dataclass(frozen=True)
class StartSpec:
    """The judges' start: a box and a cardinal heading; x, y, yaw pin the exact pose."""

    box: str
    heading_deg: float
    x: float | None = None
    y: float | None = None
    yaw_deg: float | None = None


@dataclass(frozen=True)
class Layout:
    """Obstacles and start of one run. `start` None: the caller (or the seed) chooses it."""

    rocks: tuple[Rock, ...] = ()
    craters: tuple[Crater, ...] = ()
    start: StartSpec | None = None
    source: str = ""  # "seed 7" or the world file's name, for messages and plots


class Pose(NamedTuple):
    """A robot pose in the arena frame: centre of the footprint (m), yaw (deg, CCW)."""

    x: float
    y: float
    yaw_deg: float


# ---- footprint geometry ---------------------------------------------------------------------


def footprint_corners(x: float, y: float, yaw: float, length: float, width: float,
                      ) -> tuple[tuple[float, float], ...]:
    """Corners front-left, front-right, rear-left, rear-right (world x, y); yaw in radians."""
    c, s = math.cos(yaw), math.sin(yaw)
    hl, hw = length / 2.0, width / 2.0
    nl, nw = -hl, -hw
    # Written out (the chassis asks on every physics piece), the same sums as a loop over
    # the corners' (forward, left) offsets.
    return ((x + hl * c - hw * s, y + hl * s + hw * c),
            (x + hl * c - nw * s, y + hl * s + nw * c),
            (x + nl * c - hw * s, y + nl * s + hw * c),
            (x + nl * c - nw * s, y + nl * s + nw * c))


def disc_overlap(x: float, y: float, yaw: float, length: float, width: float,
                 cx: float, cy: float, r: float) -> tuple[float, float, float]:
    """How deep a disc (centre cx, cy, radius r) overlaps the footprint, and which way to move
    the footprint to get out: (depth m, unit nx, ny in world). depth <= 0: no overlap."""
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = cx - x, cy - y
    f = dx * c + dy * s  # disc centre in the body frame: forward, left
    lft = -dx * s + dy * c
    hl, hw = length / 2.0, width / 2.0
    qf = min(hl, max(-hl, f))
    ql = min(hw, max(-hw, lft))
    ef, el = f - qf, lft - ql
    dist = math.hypot(ef, el)
    if dist > 0.0:
        depth = r - dist
        bf, bl = -ef / dist, -el / dist  # body-frame direction from the disc to the box
    else:  # the disc's centre is inside the footprint: leave by the nearest side
        gap_f, gap_l = hl - abs(f), hw - abs(lft)
        if gap_f < gap_l:
            depth = r + gap_f
            bf, bl = (-1.0 if f >= 0 else 1.0), 0.0
        else:
            depth = r + gap_l
            bf, bl = 0.0, (-1.0 if lft >= 0 else 1.0)
    return depth, bf * c - bl * s, bf * s + bl * c


def region_of(x: float, mp: MarteParams) -> str:
    """SPEC 6.1 region of an x coordinate: "start", "obstacle" or "dig"."""
    if x < mp.start_region_end:
        return "start"
    if x < mp.dig_region_start:
        return "obstacle"
    return "dig"


def collector_span(mp: MarteParams) -> tuple[float, float]:
    """(y_min, y_max) of the collector bin behind the x = 0 wall."""
    half = mp.collector_width / 2.0
    return mp.collector_y - half, mp.collector_y + half


def box_bounds(box: str, mp: MarteParams, ap: ArenaParams) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) of a start box (SPEC 6.1: right y < 1.94, left y >= 1.94)."""
    if box == "left":
        return 0.0, mp.start_region_end, ap.start_split_y, mp.arena_width
    if box == "right":
        return 0.0, mp.start_region_end, 0.0, ap.start_split_y
    raise ValueError(f"unknown start box {box!r} (expected left or right)")


def _half_extents(yaw: float, mp: MarteParams) -> tuple[float, float]:
    """Half the footprint's axis-aligned extent in x and in y at this yaw (radians)."""
    hl, hw = mp.robot_length / 2.0, mp.robot_width / 2.0
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    return hl * c + hw * s, hl * s + hw * c


def footprint_inside(x: float, y: float, yaw: float, bounds: tuple[float, float, float, float],
                     mp: MarteParams, margin: float = 0.0) -> bool:
    """True when the whole footprint lies inside (x0, x1, y0, y1), `margin` from its edges."""
    ex, ey = _half_extents(yaw, mp)
    x0, x1, y0, y1 = bounds
    eps = 1e-9
    return (x - ex >= x0 + margin - eps and x + ex <= x1 - margin + eps
            and y - ey >= y0 + margin - eps and y + ey <= y1 - margin + eps)


# ---- start pose -----------------------------------------------------------------------------


def _rng(seed: int, stream: str) -> random.Random:
    """One independent, reproducible random stream per purpose and seed."""
    return random.Random(f"ramp-arena:{seed}:{stream}")


def start_pose(spec: StartSpec, seed: int, mp: MarteParams | None = None,
               ap: ArenaParams | None = None) -> Pose:
    """The exact start pose: the box's centre and the heading, perturbed by the seed (up to
    +-10 deg and +-0.2 m, the footprint kept wholly inside the box, SPEC 6.1); x, y and yaw
    given in the spec replace the perturbed values."""
    mp = mp or MarteParams()
    ap = ap or ArenaParams()
    rng = _rng(seed, "start")
    jitter_yaw = rng.uniform(-ap.start_yaw_jitter_deg, ap.start_yaw_jitter_deg)
    jitter_x = rng.uniform(-ap.start_xy_jitter, ap.start_xy_jitter)
    jitter_y = rng.uniform(-ap.start_xy_jitter, ap.start_xy_jitter)
    yaw_deg = spec.yaw_deg if spec.yaw_deg is not None else spec.heading_deg + jitter_yaw
    yaw_deg = math.remainder(yaw_deg, 360.0)
    x0, x1, y0, y1 = box_bounds(spec.box, mp, ap)
    ex, ey = _half_extents(math.radians(yaw_deg), mp)
    m = ap.start_margin

    def place(lo: float, hi: float, jitter: float) -> float:
        mid = (lo + hi) / 2.0
        lo, hi = lo + m, hi - m
        if lo > hi:  # the footprint does not fit at this yaw: the box's centre line
            return mid
        return min(hi, max(lo, mid + jitter))

    x = spec.x if spec.x is not None else place(x0 + ex, x1 - ex, jitter_x)
    y = spec.y if spec.y is not None else place(y0 + ey, y1 - ey, jitter_y)
    return Pose(x, y, yaw_deg)


def seeded_start(seed: int, box: str | None = None, heading_deg: float | None = None,
                 ) -> StartSpec:
    """A start box and cardinal heading drawn from the seed, unless given."""
    rng = _rng(seed, "start-box")
    drawn_box = rng.choice(START_BOXES)
    drawn_heading = rng.choice(HEADINGS_DEG)
    return StartSpec(box if box is not None else drawn_box,
                     float(heading_deg if heading_deg is not None else drawn_heading))


# ---- seeded layouts ---------------------------------------------------------------------


def random_layout(seed: int, mp: MarteParams | None = None, ap: ArenaParams | None = None,
                  start_box: str | None = None, heading_deg: float | None = None) -> Layout:
    """Three rocks and two craters placed from the seed under SPEC 6.1's rules: diameters
    and depths in range, rocks at least half as tall as wide, each disc wholly inside the
    obstacle region, no two closer than `obstacle_gap`."""
    mp = mp or MarteParams()
    ap = ap or ArenaParams()
    rng = _rng(seed, "obstacles")
    for _ in range(1000):
        placed: list[tuple[float, float, float]] = []
        rocks: list[Rock] = []
        craters: list[Crater] = []
        ok = True
        for i in range(ap.rock_count + ap.crater_count):
            is_rock = i < ap.rock_count
            d = rng.uniform(ap.rock_d_min, ap.rock_d_max) if is_rock else rng.uniform(
                ap.crater_d_min, ap.crater_d_max)
            spot = _free_spot(rng, d / 2.0, placed, mp, ap)
            if spot is None:
                ok = False
                break
            x, y = spot
            placed.append((x, y, d / 2.0))
            if is_rock:
                ratio = rng.uniform(ap.rock_height_ratio_min, ap.rock_height_ratio_max)
                rocks.append(Rock(x, y, d, d * ratio))
            else:
                depth = rng.uniform(ap.crater_depth_min, ap.crater_depth_max)
                craters.append(Crater(x, y, d, depth))
        if ok:
            return Layout(tuple(rocks), tuple(craters), seeded_start(seed, start_box,
                                                                     heading_deg),
                          source=f"seed {seed}")
    raise RuntimeError("could not place the obstacles; the obstacle region is too small")


def _free_spot(rng: random.Random, r: float, placed: list[tuple[float, float, float]],
               mp: MarteParams, ap: ArenaParams) -> tuple[float, float] | None:
    for _ in range(200):
        x = rng.uniform(mp.start_region_end + r, mp.dig_region_start - r)
        y = rng.uniform(r, mp.arena_width - r)
        if all(math.hypot(x - px, y - py) >= r + pr + ap.obstacle_gap
               for px, py, pr in placed):
            return x, y
    return None


def rule_problems(layout: Layout, seed: int = 0, mp: MarteParams | None = None,
                  ap: ArenaParams | None = None) -> list[str]:
    """Where a layout departs from SPEC 6.1's competition rules (empty: it follows them).
    World files may depart on purpose (another competition's field); seeded layouts never do.
    """
    mp = mp or MarteParams()
    ap = ap or ArenaParams()
    out: list[str] = []
    if len(layout.rocks) != ap.rock_count:
        out.append(f"{len(layout.rocks)} rocks, the rules have {ap.rock_count}")
    if len(layout.craters) != ap.crater_count:
        out.append(f"{len(layout.craters)} craters, the rules have {ap.crater_count}")
    discs: list[tuple[str, float, float, float]] = []
    for i, rock in enumerate(layout.rocks):
        name = f"rocks[{i}]"
        if not ap.rock_d_min - 1e-9 <= rock.d <= ap.rock_d_max + 1e-9:
            out.append(f"{name}: diameter {rock.d:.3f} m outside "
                       f"{ap.rock_d_min}-{ap.rock_d_max} m")
        if rock.height < ap.rock_height_ratio_min * rock.d - 1e-9:
            out.append(f"{name}: {rock.height:.3f} m tall, less than half its diameter")
        discs.append((name, rock.x, rock.y, rock.radius))
    for i, crater in enumerate(layout.craters):
        name = f"craters[{i}]"
        if not ap.crater_d_min - 1e-9 <= crater.d <= ap.crater_d_max + 1e-9:
            out.append(f"{name}: diameter {crater.d:.3f} m outside "
                       f"{ap.crater_d_min}-{ap.crater_d_max} m")
        if not 0.0 < crater.depth <= ap.crater_depth_max + 1e-9:
            out.append(f"{name}: {crater.depth:.3f} m deep, the rules allow up to "
                       f"{ap.crater_depth_max} m")
        discs.append((name, crater.x, crater.y, crater.radius))
    for name, x, y, r in discs:
        if (x - r < mp.start_region_end - 1e-9 or x + r > mp.dig_region_start + 1e-9
                or y - r < -1e-9 or y + r > mp.arena_width + 1e-9):
            out.append(f"{name}: not wholly inside the obstacle region")
    for i, (na, xa, ya, ra) in enumerate(discs):
        for nb, xb, yb, rb in discs[i + 1:]:
            if math.hypot(xa - xb, ya - yb) < ra + rb:
                out.append(f"{na} and {nb} overlap")
    if layout.start is not None:
        if layout.start.box not in START_BOXES:
            out.append(f"start.box {layout.start.box!r} is not left or right")
        else:
            pose = start_pose(layout.start, seed, mp, ap)
            if not footprint_inside(pose.x, pose.y, math.radians(pose.yaw_deg),
                                    box_bounds(layout.start.box, mp, ap), mp):
                out.append("start: the footprint is not wholly inside the start box")
            off = abs(math.remainder(pose.yaw_deg - layout.start.heading_deg, 360.0))
            if off > ap.start_yaw_jitter_deg + 1e-9:
                out.append(f"start: yaw {off:.1f} deg off the heading, the rules allow "
                           f"{ap.start_yaw_jitter_deg:g}")
    return out
