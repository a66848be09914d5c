"""Referee a mission from its `--trace` file alone (SPEC 6.1 rules, SPEC 6.3 trace format).

The trace is JSON lines: a header with the true world (`arena`, `robot` {length, width},
`rocks`, `craters`, `start`, `seed`, `fault`), then one line per 0.1 s of simulated time
(`t, x, y, yaw` in degrees, `lift, bin_kg, delivered_kg, state`). From that alone this module
finds

- **collisions**: any overlap of the footprint rectangle with a rock's disc or a wall. Contact
  counts (a wall stops a robot at contact, so a physics engine never shows more). Touching
  the x = 0 wall is **docking**, not a collision, when only the rear does it (every corner
  within `dock_tolerance_m` of the wall is a rear corner, those corners lie within the
  collector's width) and it presses no deeper than `dock_tolerance_m`;
- **crater entries**: any overlap of the footprint with a crater's disc;
- **deliveries**: every rise of `delivered_kg`, and whether the robot's rear edge was within
  `delivery_reach_m` of the x = 0 wall and within the collector's width at both samples
  around it.

An entry into any one rock, crater or wall is one event for as long as the overlap lasts.
Between two samples the pose is interpolated (x, y linearly, yaw the short way) in steps that
move no point of the footprint more than `substep_m`, so a fast pass cannot slip between two
0.1 s lines.

It shares no code with the simulator or the autonomy on purpose: a bug in their own counters
or geometry cannot hide a collision here. Pure numpy, no I/O beyond reading the file.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

# SPEC 6.1 defaults, used when the header's `arena` leaves a value out.
ARENA_LENGTH_M = 7.38
ARENA_WIDTH_M = 3.88
COLLECTOR_Y_M = 1.94
COLLECTOR_WIDTH_M = 1.65
QUALIFY_KG = 10.0
SAMPLE_FIELDS = ("t", "x", "y", "yaw", "lift", "bin_kg", "delivered_kg", "state")


class TraceError(ValueError):
    """A trace that cannot be refereed; the message names file:line and the problem."""


@dataclass(frozen=True)
class RefereeRules:
    """Tolerances of the rules (SPEC 6.1 fixes the 2 cm and 0.15 m)."""

    contact_m: float = 1e-6  # closer than this counts as touching
    dock_tolerance_m: float = 0.02
    delivery_reach_m: float = 0.15
    substep_m: float = 0.01  # no footprint point moves more than this between checks


@dataclass(frozen=True)
class Disc:
    x: float
    y: float
    radius: float


@dataclass(frozen=True)
class World:
    """The true world from a trace header."""

    length: float
    width: float
    collector_y: float
    collector_width: float
    robot_length: float
    robot_width: float
    rocks: tuple[Disc, ...]
    craters: tuple[Disc, ...]


@dataclass(frozen=True)
class Trace:
    header: dict[str, Any]
    world: World
    t: Array
    x: Array
    y: Array
    yaw: Array  # radians
    delivered_kg: Array
    states: tuple[str, ...]


@dataclass(frozen=True)
class Event:
    """One collision, crater entry or delivery away from the collector."""

    kind: str  # "collision", "crater_entry", "bad_delivery"
    what: str  # "rock 2", "wall x=0", "crater 1", "delivery"
    t_start: float
    t_end: float
    depth_m: float  # deepest overlap (0 for a delivery)
    x: float  # robot pose at the deepest point (at the start, for a delivery)
    y: float
    yaw_deg: float
    kg: float = 0.0  # for a delivery


@dataclass(frozen=True)
class RefereeReport:
    collisions: int
    crater_entries: int
    delivered_kg: float  # what the trace says was delivered in total
    delivered_at_collector_kg: float
    delivered_elsewhere_kg: float
    dock_contacts: int  # times the rear touched the wall at the collector (not collisions)
    samples: int
    duration_s: float
    events: tuple[Event, ...] = field(default=())

    @property
    def qualifies(self) -> bool:
        """SPEC 6.3: at least 10 kg delivered, no collision, no crater entry."""
        return (self.delivered_at_collector_kg >= QUALIFY_KG and self.collisions == 0
                and self.crater_entries == 0)

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["qualifies"] = self.qualifies
        return out


# -- reading -----------------------------------------------------------------------------------
def read_trace(source: str | Path | Iterable[str]) -> Trace:
    """Parse a trace file (or its lines). Raises TraceError naming file:line."""
    name = str(source) if isinstance(source, str | Path) else "<trace>"
    if isinstance(source, str | Path):
        with open(source, encoding="utf-8") as f:
            lines = f.read().splitlines()
    else:
        lines = list(source)
    rows: list[dict[str, Any]] = []
    header: dict[str, Any] | None = None
    world: World | None = None
    for number, text in enumerate(lines, 1):
        if not text.strip():
            continue
        try:
            obj = json.loads(text)
        except json.JSONDecodeError as exc:
            raise TraceError(f"{name}:{number}: not JSON: {exc.msg}") from exc
        if not isinstance(obj, dict):
            raise TraceError(f"{name}:{number}: expected a JSON object")
        if header is None:
            header = obj
            world = _world(header, f"{name}:{number}")
            continue
        for key in SAMPLE_FIELDS[:-1]:
            value = obj.get(key)
            if not isinstance(value, int | float) or isinstance(value, bool) \
                    or not math.isfinite(value):
                raise TraceError(f"{name}:{number}: {key}: expected a number, got {value!r}")
        rows.append(obj)
    if header is None or world is None:
        raise TraceError(f"{name}: empty trace (no header line)")
    if not rows:
        raise TraceError(f"{name}: the trace has a header but no samples")
    t = np.array([r["t"] for r in rows], dtype=float)
    if np.any(np.diff(t) < 0):
        bad = int(np.argmax(np.diff(t) < 0)) + 2
        raise TraceError(f"{name}: sample {bad}: t goes backwards")
    return Trace(header, world, t, np.array([r["x"] for r in rows], dtype=float),
                 np.array([r["y"] for r in rows], dtype=float),
                 np.radians(np.array([r["yaw"] for r in rows], dtype=float)),
                 np.array([r["delivered_kg"] for r in rows], dtype=float),
                 tuple(str(r.get("state", "")) for r in rows))


def _number(block: Mapping[str, Any], keys: Sequence[str], default: float | None,
            where: str) -> float:
    for key in keys:
        if key in block:
            value = block[key]
            if isinstance(value, int | float) and not isinstance(value, bool) \
                    and math.isfinite(value):
                return float(value)
            raise TraceError(f"{where}: {keys[0]}: expected a number, got {value!r}")
    if default is None:
        raise TraceError(f"{where}: {keys[0]}: missing")
    return default


def _discs(header: Mapping[str, Any], key: str, where: str) -> tuple[Disc, ...]:
    items = header.get(key, [])
    if not isinstance(items, list):
        raise TraceError(f"{where}: {key}: expected a list")
    out = []
    for k, item in enumerate(items):
        if not isinstance(item, dict):
            raise TraceError(f"{where}: {key}[{k}]: expected an object with x, y, d")
        here = f"{where}: {key}[{k}]"
        d = _number(item, ("d", "diameter"), None, here)
        out.append(Disc(_number(item, ("x",), None, here), _number(item, ("y",), None, here),
                        0.5 * d))
    return tuple(out)


def _world(header: Mapping[str, Any], where: str) -> World:
    arena = header.get("arena") or {}
    robot = header.get("robot")
    if not isinstance(arena, dict):
        raise TraceError(f"{where}: arena: expected an object")
    if not isinstance(robot, dict):
        raise TraceError(f"{where}: robot: expected an object with length and width")
    return World(
        _number(arena, ("length", "length_m"), ARENA_LENGTH_M, f"{where}: arena"),
        _number(arena, ("width", "width_m"), ARENA_WIDTH_M, f"{where}: arena"),
        _number(arena, ("collector_y", "collector_y_m"), COLLECTOR_Y_M, f"{where}: arena"),
        _number(arena, ("collector_width", "collector_width_m"), COLLECTOR_WIDTH_M,
                f"{where}: arena"),
        _number(robot, ("length", "length_m"), None, f"{where}: robot"),
        _number(robot, ("width", "width_m"), None, f"{where}: robot"),
        _discs(header, "rocks", where), _discs(header, "craters", where))


# -- geometry ----------------------------------------------------------------------------------
def _subsample(trace: Trace, rules: RefereeRules) -> tuple[Array, Array, Array, Array]:
    """Poses (t, x, y, yaw) at every sample and between samples, close enough together."""
    w = trace.world
    reach = math.hypot(w.robot_length, w.robot_width) / 2
    dx, dy = np.diff(trace.x), np.diff(trace.y)
    dyaw = np.remainder(np.diff(trace.yaw) + math.pi, 2 * math.pi) - math.pi
    motion = np.hypot(dx, dy) + np.abs(dyaw) * reach
    steps = np.clip(np.ceil(motion / rules.substep_m), 1, 100_000).astype(int)
    seg = np.repeat(np.arange(len(steps)), steps)
    first = np.concatenate([[0], np.cumsum(steps)[:-1]])
    frac = (np.arange(len(seg)) - first[seg] + 1) / steps[seg]
    t = np.concatenate([trace.t[:1], trace.t[seg] + frac * np.diff(trace.t)[seg]])
    x = np.concatenate([trace.x[:1], trace.x[seg] + frac * dx[seg]])
    y = np.concatenate([trace.y[:1], trace.y[seg] + frac * dy[seg]])
    yaw = np.concatenate([trace.yaw[:1], trace.yaw[seg] + frac * dyaw[seg]])
    return t, x, y, yaw


def _corners(world: World, x: Array, y: Array, yaw: Array) -> tuple[Array, Array]:
    """Corner coordinates (N, 4): front-left, front-right, rear-right, rear-left."""
    hl, hw = world.robot_length / 2, world.robot_width / 2
    u = np.array([hl, hl, -hl, -hl])
    v = np.array([hw, -hw, -hw, hw])
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    return x[:, None] + c * u - s * v, y[:, None] + s * u + c * v


def _disc_gap(world: World, discs: Sequence[Disc], x: Array, y: Array,
              yaw: Array) -> Array:
    """(N, M) gap between the footprint and each disc (negative: overlap)."""
    if not discs:
        return np.zeros((len(x), 0))
    hl, hw = world.robot_length / 2, world.robot_width / 2
    cx = np.array([d.x for d in discs])[None, :] - x[:, None]
    cy = np.array([d.y for d in discs])[None, :] - y[:, None]
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    u = np.abs(cx * c + cy * s) - hl
    v = np.abs(-cx * s + cy * c) - hw
    outside = np.hypot(np.maximum(u, 0.0), np.maximum(v, 0.0))
    inside = np.minimum(np.maximum(u, v), 0.0)
    return outside + inside - np.array([d.radius for d in discs])[None, :]


def _wall_gaps(world: World, cx: Array, cy: Array,
               rules: RefereeRules) -> tuple[Array, NDArray[np.bool_]]:
    """(N, 4) gaps to the walls x=0, x=L, y=0, y=W; and which x=0 contacts are docking."""
    gaps = np.column_stack([cx.min(axis=1), world.length - cx.max(axis=1), cy.min(axis=1),
                            world.width - cy.max(axis=1)])
    tol = rules.dock_tolerance_m
    near = cx <= tol  # corners within the docking band
    rear_only = ~near[:, 0] & ~near[:, 1]
    half = world.collector_width / 2
    inside_span = (np.abs(cy - world.collector_y) <= half + rules.contact_m) | ~near
    docking: NDArray[np.bool_] = rear_only & inside_span.all(axis=1) & (gaps[:, 0] >= -tol)
    return gaps, docking


def _rear_at_collector(world: World, x: Array, y: Array, yaw: Array,
                       rules: RefereeRules) -> NDArray[np.bool_]:
    cx, cy = _corners(world, x, y, yaw)
    rear_x, rear_y = cx[:, 2:], cy[:, 2:]
    half = world.collector_width / 2
    near = np.all(rear_x <= rules.delivery_reach_m, axis=1)
    within = np.all(np.abs(rear_y - world.collector_y) <= half + rules.contact_m, axis=1)
    return np.asarray(near & within, dtype=bool)


# -- refereeing --------------------------------------------------------------------------------
def referee(trace: Trace | str | Path | Iterable[str],
            rules: RefereeRules | None = None) -> RefereeReport:
    """Check SPEC 6.1's rules on a trace (or a trace file, or its lines)."""
    rules = rules or RefereeRules()
    if not isinstance(trace, Trace):
        trace = read_trace(trace)
    w = trace.world
    t, x, y, yaw = _subsample(trace, rules)
    cx, cy = _corners(w, x, y, yaw)
    wall_gap, docking = _wall_gaps(w, cx, cy, rules)
    wall_hit = wall_gap <= rules.contact_m
    dock_contact = wall_hit[:, 0] & docking
    wall_hit[:, 0] &= ~docking
    rock_gap = _disc_gap(w, w.rocks, x, y, yaw)
    crater_gap = _disc_gap(w, w.craters, x, y, yaw)
    events: list[Event] = []
    pose = (t, x, y, yaw)
    wall_names = ("wall x=0", f"wall x={w.length:g}", "wall y=0", f"wall y={w.width:g}")
    for k, name in enumerate(wall_names):
        events += _episodes("collision", name, wall_hit[:, k], wall_gap[:, k], pose)
    for k in range(len(w.rocks)):
        events += _episodes("collision", f"rock {k}", rock_gap[:, k] <= rules.contact_m,
                            rock_gap[:, k], pose)
    for k in range(len(w.craters)):
        events += _episodes("crater_entry", f"crater {k}", crater_gap[:, k] <= rules.contact_m,
                            crater_gap[:, k], pose)
    at_collector_kg, elsewhere_kg, bad = _deliveries(trace, rules)
    events += bad
    events.sort(key=lambda e: (e.t_start, e.kind, e.what))
    return RefereeReport(
        collisions=sum(e.kind == "collision" for e in events),
        crater_entries=sum(e.kind == "crater_entry" for e in events),
        delivered_kg=float(trace.delivered_kg[-1]),
        delivered_at_collector_kg=round(at_collector_kg, 6),
        delivered_elsewhere_kg=round(elsewhere_kg, 6),
        dock_contacts=int(np.count_nonzero(np.diff(dock_contact.astype(int),
                                                   prepend=0) == 1)),
        samples=len(trace.t),
        duration_s=float(trace.t[-1] - trace.t[0]),
        events=tuple(events))


def _episodes(kind: str, what: str, active: NDArray[np.bool_], gap: Array,
              pose: tuple[Array, Array, Array, Array]) -> list[Event]:
    """One event per run of consecutive overlapping poses."""
    if not active.any():
        return []
    edges = np.diff(active.astype(int), prepend=0, append=0)
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
    t, x, y, yaw = pose
    out = []
    for a, b in zip(starts, ends, strict=True):
        worst = a + int(np.argmin(gap[a:b]))
        out.append(Event(kind, what, float(t[a]), float(t[b - 1]),
                         round(max(0.0, -float(gap[worst])), 6), float(x[worst]),
                         float(y[worst]), math.degrees(float(yaw[worst]))))
    return out


def _deliveries(trace: Trace, rules: RefereeRules) -> tuple[float, float, list[Event]]:
    """Split every rise of delivered_kg by whether the rear was at the collector."""
    rise = np.diff(trace.delivered_kg)
    ok = _rear_at_collector(trace.world, trace.x, trace.y, trace.yaw, rules)
    good_pair = ok[:-1] & ok[1:]
    delivering = rise > 1e-9
    at_collector = float(rise[delivering & good_pair].sum())
    elsewhere_mask = delivering & ~good_pair
    events = []
    if elsewhere_mask.any():
        edges = np.diff(elsewhere_mask.astype(int), prepend=0, append=0)
        for a, b in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0], strict=True):
            events.append(Event("bad_delivery", "delivery", float(trace.t[a]),
                                float(trace.t[b]), 0.0, float(trace.x[a]), float(trace.y[a]),
                                math.degrees(float(trace.yaw[a])),
                                round(float(rise[a:b].sum()), 6)))
    return at_collector, float(rise[elsewhere_mask].sum()), events
