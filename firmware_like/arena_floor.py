"""The RMC arena as a part of MARTE's simulated world: the floor the chassis stands on.

Walls, rocks, craters and the terrain's undulation (`firmware_like.terrain`), and the
referee's counts (SPEC 6.1: collisions and crater entries begun, a wheel trapped in a crater).
The chassis (`firmware_like.marte.MarteWorld`) moves itself and, in each of its physics pieces,
asks its floor to stop it at a wall or a rock (`clamp`, `push_off_rocks`), to count what it
touches (`update_contacts`) and to rest it on the ground (`rest`: height, pitch, roll, and
the traction a crater leaves it). Every floating point operation is the one MARTE's single
model made, in the same order, so a seeded run gives the same result to the last bit.
"""

from __future__ import annotations

import math
from math import sin
from typing import Any

from firmware_like.arena import Layout, collector_span, disc_overlap
from firmware_like.arena_params import ArenaParams
from firmware_like.marte_params import MarteParams
from firmware_like.terrain import Terrain


class ArenaFloor:
    """The arena a chassis of `params`' footprint drives in; `layout` None is an empty arena
    with level ground."""

    def __init__(self, params: MarteParams, arena: ArenaParams, seed: int,
                 layout: Layout | None) -> None:
        p = self.params = params
        self.arena = arena
        self.layout = layout if layout is not None else Layout(source="empty arena")
        self.terrain = Terrain(self.layout, self.arena, seed, flat=layout is None)
        self.flat = layout is None
        self.rocks = [(r.x, r.y, r.radius) for r in self.layout.rocks]
        self.craters = [(c.x, c.y, c.radius) for c in self.layout.craters]
        self.reach = math.hypot(p.robot_length, p.robot_width) / 2.0 + max(
            [r for *_, r in self.rocks + self.craters] + [0.0])
        self.collisions = 0
        self.crater_entries = 0
        self.collision_log: list[tuple[float, str]] = []
        self.crater_log: list[tuple[float, str]] = []
        self.trapped = False
        #: What a crater leaves of the wheels' grip (1 on firm ground, 0 trapped).
        self.traction = 1.0
        self.touching: set[str] = set()
        # The chassis' wheel geometry, worked out once (the params are frozen).
        hb, ht = p.wheelbase / 2.0, p.track_width / 2.0
        self._wheels = ((hb, ht), (hb, -ht), (-hb, ht), (-hb, -ht))  # fl, fr, rl, rr
        self._radius, self._half_w = p.wheel_diameter / 2.0, p.wheel_width / 2.0
        #: A chassis centre at least this far from every rock and crater centre has no wheel
        #: near enough to one for `Terrain.wheel_contact` to look at it (its reach, plus a
        #: centimetre against rounding): such a wheel rests on the bare ground.
        self._wheels_clear = (math.hypot(hb, ht) + self._radius + self._half_w
                              + self.terrain.reach + 0.01)
        # What a chassis on bare ground gets, by the same expressions as `rest`.
        self._bare_trapped = arena.crater_trap_sink <= 0.0
        self._bare_traction = 1.0 - (1.0 - arena.crater_slow_min) * max(0.0, 0.0) / (
            arena.crater_trap_sink)
        # What the last pose gave (the body, then its x, y, heading): the floor is fixed, so
        # the same pose gives the same answer, and a robot standing still (digging, dumping:
        # half of a mission's pieces) is not worked out again. `_held` is the body's (x, y)
        # after `clamp` and `push_off_rocks`, `_contacts` what `contacts` found, `_rest`
        # the (z, pitch, roll, trapped, traction) `rest` set.
        self._held_at: tuple[Any, float, float, float] | None = None
        self._held: tuple[float, float] = (0.0, 0.0)
        self._contacts_at: tuple[Any, float, float, float] | None = None
        self._contacts: tuple[set[str], set[str]] = (set(), set())
        self._rest_at: tuple[Any, float, float, float] | None = None
        self._rest: tuple[float, float, float, bool, float] = (0.0, 0.0, 0.0, False, 1.0)

    def hold(self, body: Any) -> None:
        """Walls and rocks stop the robot: `clamp`, then `push_off_rocks` when there are
        rocks, as the chassis moves (the answer for its last pose remembered)."""
        at = (body, body.x, body.y, body.heading)
        if at == self._held_at:
            body.x, body.y = self._held
            return
        self.clamp(body)
        if self.rocks:
            self.push_off_rocks(body)
        self._held_at = at
        self._held = (body.x, body.y)

    def clamp(self, body: Any) -> None:
        """Walls stop the robot: push the footprint back inside, keeping its heading."""
        p = self.params
        (x0, y0), (x1, y1), (x2, y2), (x3, y3) = body.corners()
        lo_x, hi_x = min(x0, x1, x2, x3), max(x0, x1, x2, x3)
        lo_y, hi_y = min(y0, y1, y2, y3), max(y0, y1, y2, y3)
        if lo_x < 0.0:
            body.x -= lo_x
        elif hi_x > p.arena_length:
            body.x -= hi_x - p.arena_length
        if lo_y < 0.0:
            body.y -= lo_y
        elif hi_y > p.arena_width:
            body.y -= hi_y - p.arena_width

    def push_off_rocks(self, body: Any) -> None:
        """A rock stops the robot: a footprint deeper into a rock's disc than a wheel can ride
        up its flank is pushed back out, keeping its heading (it slides along the rock)."""
        p, ride = self.params, self.arena.rock_ride_up
        moved = False
        for cx, cy, r in self.rocks:
            if (cx - body.x) ** 2 + (cy - body.y) ** 2 >= self.reach ** 2:
                continue
            depth, nx, ny = disc_overlap(body.x, body.y, body.heading, p.robot_length,
                                         p.robot_width, cx, cy, r)
            limit = min(ride, r)
            if depth > limit:
                body.x += nx * (depth - limit)
                body.y += ny * (depth - limit)
                moved = True
        if moved:
            self.clamp(body)

    def contacts(self, body: Any) -> tuple[set[str], set[str]]:
        """(what the footprint collides with, craters it overlaps) now, by SPEC 6.1 (the
        same two sets again while the pose stays: callers only read them)."""
        at = (body, body.x, body.y, body.heading)
        if at == self._contacts_at:
            return self._contacts
        p, a = self.params, self.arena
        eps = a.contact_epsilon
        corners = body.corners()
        (x0, y0), (x1, y1), (x2, y2), (x3, y3) = corners
        lo_x = min(x0, x1, x2, x3)
        hits: set[str] = set()
        if lo_x <= eps:
            at_x0 = [i for i, c in enumerate(corners) if c[0] <= eps]
            lo, hi = collector_span(p)
            docking = (all(i >= 2 for i in at_x0)  # only rear corners touch
                       and lo_x >= -a.docking_tolerance
                       and all(lo <= corners[i][1] <= hi for i in at_x0))
            if not docking:
                hits.add("wall x=0")
        if max(x0, x1, x2, x3) >= p.arena_length - eps:
            hits.add(f"wall x={p.arena_length:g}")
        if min(y0, y1, y2, y3) <= eps:
            hits.add("wall y=0")
        if max(y0, y1, y2, y3) >= p.arena_width - eps:
            hits.add(f"wall y={p.arena_width:g}")
        craters: set[str] = set()
        bx, by, reach2 = body.x, body.y, self.reach ** 2
        for kind, discs, out in (("rock", self.rocks, hits), ("crater", self.craters,
                                                                craters)):
            for i, (cx, cy, r) in enumerate(discs):
                if (cx - bx) ** 2 + (cy - by) ** 2 >= reach2:
                    continue
                depth, _, _ = disc_overlap(bx, by, body.heading, p.robot_length,
                                           p.robot_width, cx, cy, r)
                if depth > 0.0:
                    out.add(f"{kind} {i}")
        self._contacts_at = at
        self._contacts = (hits, craters)
        return hits, craters

    def update_contacts(self, body: Any, count: bool) -> None:
        """Count each collision and crater entry once, when it begins."""
        hits, craters = self.contacts(body)
        if not hits and not craters and not self.touching:
            return  # clear of everything, as before: nothing begins, nothing to remember
        now = hits | craters
        if count:
            for what in sorted(hits - self.touching):
                self.collisions += 1
                self.collision_log.append((body.time, what))
            for what in sorted(craters - self.touching):
                self.crater_entries += 1
                self.crater_log.append((body.time, what))
        self.touching = now

    def rest(self, body: Any) -> None:
        """Rest the chassis on its four wheels: height, pitch and roll from where each wheel
        touches the terrain; the deepest wheel in a crater sets the traction.

        Far from every rock and crater (the usual case) each wheel rests on the bare ground
        and sinks nowhere, so only the ground's height is worked out: the same numbers as the
        full contact model gives there, for a quarter of the work."""
        if self.flat:
            return
        at = (body, body.x, body.y, body.heading)
        if at == self._rest_at:
            body.z, body.pitch, body.roll, self.trapped, self.traction = self._rest
            return
        p, a = self.params, self.arena
        c, s = math.cos(body.heading), math.sin(body.heading)
        bx, by = body.x, body.y
        terrain = self.terrain
        if terrain.clear_of_obstacles(bx, by, self._wheels_clear):
            # `terrain.ground_at` at each wheel, written out (its sum in its order).
            waves = terrain._waves
            z4: list[float] = []
            for f, lft in self._wheels:
                wx, wy = bx + f * c - lft * s, by + f * s + lft * c
                h = 0.0
                for amp, kx, ky, phase in waves:
                    h += amp * sin(kx * wx + ky * wy + phase)
                z4.append(h)
            fl, fr, rl, rr = z4
            trapped, traction = self._bare_trapped, self._bare_traction
        else:
            radius, half_w = self._radius, self._half_w
            z: list[float] = []
            sink = 0.0
            for f, lft in self._wheels:
                wx, wy = bx + f * c - lft * s, by + f * s + lft * c
                h, ground = terrain.wheel_contact(wx, wy, c, s, radius, half_w)
                z.append(h)
                sink = max(sink, ground - h)
            fl, fr, rl, rr = z
            trapped = sink >= a.crater_trap_sink
            traction = 0.0 if trapped else (
                1.0 - (1.0 - a.crater_slow_min) * max(0.0, sink) / a.crater_trap_sink)
        body.z = (fl + fr + rl + rr) / 4.0
        body.pitch = math.asin(max(-1.0, min(1.0, ((rl + rr) - (fl + fr)) / (2.0 * p.wheelbase))))
        across = 2.0 * p.track_width * math.cos(body.pitch)
        body.roll = math.asin(max(-1.0, min(1.0, ((fl + rl) - (fr + rr)) / across)))
        self.trapped = trapped
        self.traction = traction
        self._rest_at = at
        self._rest = (body.z, body.pitch, body.roll, trapped, traction)
