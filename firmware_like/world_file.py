"""World files (`--world FILE`, SPEC 6.1): a fixed layout, so a team can replay a real run.

    start: {box: left, heading: 90}        # optional x, y (m) and yaw (deg) pin the pose
    rocks:   [{x: 2.10, y: 0.90, d: 0.25}, {x: 3.30, y: 2.60, d: 0.12, height: 0.10}]
    craters: [{x: 3.90, y: 1.10, d: 0.30, depth: 0.25}]
    description: any text                  # optional

Any layout inside the arena is accepted, not only the competition's (another competition's
field, a test course): `arena.rule_problems` says where it departs from the rules. Every error
names the file, the line, the key path and what was expected, all of them in one pass:
`world.yaml:3: rocks[1].d: expected a diameter in metres > 0, got 'big'`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from firmware_like.arena import (
    HEADINGS_DEG,
    START_BOXES,
    Crater,
    Layout,
    Rock,
    StartSpec,
    box_bounds,
    disc_overlap,
    footprint_inside,
)
from firmware_like.arena_params import ArenaParams
from firmware_like.marte_params import MarteParams
from ramp.common.yamlload import LinedList, LinedMap, YamlError, parse, read_text, shown


class WorldError(ValueError):
    """One problem in a world file, located like a config error: file:line: key: what."""

    def __init__(self, message: str, *, file: str, line: int = 0, key: str = "") -> None:
        self.file, self.line, self.key, self.detail = file, line, key, message
        where = f"{file}:{line}" if line else file
        super().__init__(": ".join(p for p in (where, key, message) if p))


class WorldFileError(ValueError):
    """Every problem found in one world file; `errors` lists them, str() has one a line."""

    def __init__(self, errors: list[WorldError]) -> None:
        self.errors = errors
        super().__init__("\n".join(str(e) for e in errors))


def load_world(path: str | Path, mp: MarteParams | None = None,
               ap: ArenaParams | None = None) -> Layout:
    """Read and check a world file; raises WorldFileError listing every problem."""
    name = str(path)
    try:
        text = read_text(path, what="a world file")
    except YamlError as exc:
        raise WorldFileError([WorldError(exc.problem, file=name, line=exc.line)]) from None
    return parse_world(text, name, mp, ap)


def parse_world(text: str, name: str = "world.yaml", mp: MarteParams | None = None,
                ap: ArenaParams | None = None) -> Layout:
    """Check world-file text; returns the Layout or raises WorldFileError."""
    checker = _Checker(name, mp or MarteParams(), ap or ArenaParams())
    layout = checker.world(text)
    if checker.errors or layout is None:
        raise WorldFileError(checker.errors)
    return layout


#: Smallest obstacle diameter: below it a crater's profile (depth / r^2) overflowed and the
#: ray caster returned NaN ranges (d: 1e-300 was accepted); a 1 cm obstacle is already far
#: below the LIDAR's resolution at the arena's distances.
MIN_DIAMETER_M = 0.01
#: Tallest rock and deepest crater: the walls stand 1 m; 10 m leaves room for any course, and
#: `depth: 1.0e+308` overflowed the same way (the mission then detected no obstacle at all).
MAX_SIZE_M = 10.0

_TOP = ("start", "rocks", "craters", "description")
_START = ("box", "heading", "x", "y", "yaw")
_ROCK = ("x", "y", "d", "height")
_CRATER = ("x", "y", "d", "depth")


class _Checker:
    """Walks the YAML tree collecting every error instead of stopping at the first."""

    def __init__(self, file: str, mp: MarteParams, ap: ArenaParams) -> None:
        self.file, self.mp, self.ap = file, mp, ap
        self.errors: list[WorldError] = []

    def err(self, key: str, line: int, message: str) -> None:
        self.errors.append(WorldError(message, file=self.file, line=line, key=key))

    def world(self, text: str) -> Layout | None:
        try:
            root = parse(text)
        except YamlError as exc:
            self.err("", exc.line, exc.problem)
            return None
        if root is None:
            root = LinedMap()
            root.line = 1
        if not isinstance(root, LinedMap):
            self.err("", 1, f"expected a mapping with start, rocks and craters, got "
                     f"{shown(root)}")
            return None
        self.keys(root, "", _TOP)
        start = self.start(root)
        rocks = tuple(r for r in self.items(root, "rocks", self.rock) if isinstance(r, Rock))
        craters = tuple(c for c in self.items(root, "craters", self.crater)
                        if isinstance(c, Crater))
        if start is not None:
            self.start_clear(start, root.lines.get("start", root.line), rocks, craters)
        desc = root.get("description")
        if desc is not None and not isinstance(desc, str):
            self.err("description", root.lines.get("description", root.line),
                     f"expected text, got {shown(desc)}")
        return Layout(rocks, craters, start, source=self.file)

    def keys(self, node: LinedMap, path: str, allowed: tuple[str, ...]) -> None:
        prefix = f"{path}." if path else ""
        for key, line in node.duplicates:
            self.err(f"{prefix}{key}", line, "key given twice")
        for key in node:
            if key not in allowed:
                self.err(f"{prefix}{key}", node.lines.get(key, node.line),
                         f"unknown key (expected one of: {', '.join(allowed)})")

    def number(self, node: LinedMap, key: str, path: str, what: str, *, required: bool,
               lo: float | None = None, lo_open: bool = False) -> float | None:
        line = node.lines.get(key, node.line)
        if key not in node:
            if required:
                self.err(f"{path}.{key}", node.line, f"missing; expected {what}")
            return None
        value = node[key]
        bad = isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(
            value)
        if not bad and lo is not None:
            bad = value <= lo if lo_open else value < lo
        if bad:
            self.err(f"{path}.{key}", line, f"expected {what}, got {shown(value)}")
            return None
        return float(value)

    def at_most(self, node: LinedMap, key: str, path: str, value: float | None
                ) -> float | None:
        """A rock's height or a crater's depth up to `MAX_SIZE_M`; None (and an error)
        above it."""
        if value is not None and value > MAX_SIZE_M:
            self.err(f"{path}.{key}", node.lines.get(key, node.line),
                     f"expected at most {MAX_SIZE_M:g} m, got {value:g}")
            return None
        return value

    def start(self, root: LinedMap) -> StartSpec | None:
        if "start" not in root:
            return None
        node = root["start"]
        line = root.lines.get("start", root.line)
        if not isinstance(node, LinedMap):
            self.err("start", line, f"expected a mapping like {{box: left, heading: 90}}, "
                     f"got {shown(node)}")
            return None
        self.keys(node, "start", _START)
        box = node.get("box")
        if box not in START_BOXES:
            where = node.lines.get("box", node.line)
            got = "missing" if "box" not in node else f"got {shown(box)}"
            self.err("start.box", where, f"expected left or right, {got}")
            box = None
        heading = node.get("heading")
        ok_heading = (not isinstance(heading, bool) and isinstance(heading, int | float)
                      and heading in HEADINGS_DEG)
        if not ok_heading:
            where = node.lines.get("heading", node.line)
            got = "missing" if "heading" not in node else f"got {shown(heading)}"
            self.err("start.heading", where, f"expected one of 0, 90, 180, 270 (degrees), {got}")
        x = self.number(node, "x", "start", "an x in metres", required=False)
        y = self.number(node, "y", "start", "a y in metres", required=False)
        yaw = self.number(node, "yaw", "start", "a yaw in degrees", required=False)
        if box is None or not isinstance(heading, int | float) or not ok_heading:
            return None
        spec = StartSpec(str(box), float(heading), x, y, yaw)
        if x is not None and y is not None:
            yaw_rad = math.radians(yaw if yaw is not None else float(heading))
            arena = (0.0, self.mp.arena_length, 0.0, self.mp.arena_width)
            if not footprint_inside(x, y, yaw_rad, arena, self.mp):
                self.err("start", line, f"the footprint at x {x:g}, y {y:g}, yaw "
                         f"{math.degrees(yaw_rad):g} is not wholly inside the "
                         f"{self.mp.arena_length} x {self.mp.arena_width} m arena")
        return spec

    def start_clear(self, spec: StartSpec, line: int, rocks: tuple[Rock, ...],
                    craters: tuple[Crater, ...]) -> None:
        """The start must not begin in contact: the referee would count a collision the
        run never drove into, and the physics would push the robot out of a rock unseen.
        An exact pose is checked as it is; a box's pose comes from the seed anywhere in the
        box, so no obstacle may reach into the box."""
        discs = [(f"rocks[{i}]", r.x, r.y, r.d / 2.0) for i, r in enumerate(rocks)]
        discs += [(f"craters[{i}]", c.x, c.y, c.d / 2.0) for i, c in enumerate(craters)]
        if spec.x is not None and spec.y is not None:
            yaw_deg = spec.yaw_deg if spec.yaw_deg is not None else spec.heading_deg
            yaw = math.radians(yaw_deg)
            where = f"the footprint at x {spec.x:g}, y {spec.y:g}, yaw {yaw_deg:g}"
            arena = (0.0, self.mp.arena_length, 0.0, self.mp.arena_width)
            if not footprint_inside(spec.x, spec.y, yaw, arena, self.mp,
                                    margin=self.ap.contact_epsilon):
                self.err("start", line, f"{where} touches a wall; expected a start clear "
                         "of the walls")
            for name, cx, cy, r in discs:
                depth, _, _ = disc_overlap(spec.x, spec.y, yaw, self.mp.robot_length,
                                           self.mp.robot_width, cx, cy, r)
                if depth > 0.0:
                    self.err("start", line, f"{where} overlaps {name} at x {cx:g}, y "
                             f"{cy:g}; expected a start clear of every obstacle")
            return
        x0, x1, y0, y1 = box_bounds(spec.box, self.mp, self.ap)
        for name, cx, cy, r in discs:
            nx, ny = min(max(cx, x0), x1), min(max(cy, y0), y1)
            if math.hypot(cx - nx, cy - ny) < r:
                self.err("start", line, f"{name} at x {cx:g}, y {cy:g} reaches into the "
                         f"{spec.box} start box, where the seed places the robot; expected "
                         "the box clear, or start x, y (and yaw) clear of it")

    def items(self, root: LinedMap, key: str, check: Any) -> list[object]:
        if key not in root or root[key] is None:
            return []
        seq = root[key]
        line = root.lines.get(key, root.line)
        if not isinstance(seq, LinedList):
            self.err(key, line, f"expected a list of {{x, y, d}} mappings, got "
                     f"{shown(seq)}")
            return []
        out: list[object] = []
        for i, item in enumerate(seq):
            path = f"{key}[{i}]"
            if not isinstance(item, LinedMap):
                self.err(path, seq.lines[i], f"expected a mapping like {{x: 2.1, y: 0.9, "
                         f"d: 0.25}}, got {shown(item)}")
                continue
            out.append(check(item, path))
        return out

    def disc(self, node: LinedMap, path: str, allowed: tuple[str, ...],
             ) -> tuple[float, float, float] | None:
        self.keys(node, path, allowed)
        x = self.number(node, "x", path, "an x in metres", required=True)
        y = self.number(node, "y", path, "a y in metres", required=True)
        d = self.number(node, "d", path, "a diameter in metres > 0", required=True, lo=0.0,
                        lo_open=True)
        if d is not None and d < MIN_DIAMETER_M:
            self.err(f"{path}.d", node.lines.get("d", node.line),
                     f"expected a diameter of {MIN_DIAMETER_M:g} m or more, got {d:g}")
            d = None
        if x is None or y is None or d is None:
            return None
        r = d / 2.0
        if x - r < 0 or x + r > self.mp.arena_length or y - r < 0 or y + r > self.mp.arena_width:
            self.err(path, node.line, f"the disc at x {x:g}, y {y:g}, d {d:g} is not wholly "
                     f"inside the {self.mp.arena_length} x {self.mp.arena_width} m arena")
            return None
        return x, y, d

    def rock(self, node: LinedMap, path: str) -> Rock | None:
        disc = self.disc(node, path, _ROCK)
        height = self.at_most(node, "height", path, self.number(
            node, "height", path, "a height in metres > 0", required=False, lo=0.0,
            lo_open=True))
        if disc is None:
            return None
        x, y, d = disc
        return Rock(x, y, d, height if height is not None
                    else d * self.ap.default_rock_height_ratio)

    def crater(self, node: LinedMap, path: str) -> Crater | None:
        disc = self.disc(node, path, _CRATER)
        depth = self.at_most(node, "depth", path, self.number(
            node, "depth", path, "a depth in metres > 0", required=False, lo=0.0,
            lo_open=True))
        if disc is None:
            return None
        x, y, d = disc
        if depth is None:
            depth = min(self.ap.crater_depth_max, d * self.ap.default_crater_depth_ratio)
        return Crater(x, y, d, depth)
