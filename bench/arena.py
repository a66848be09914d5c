"""`arena`: CPU cost of the simulated arena: one physics step, one emulated LIDAR scan.

A 10-minute mission at 100 Hz is 60 000 world steps and, at the UTM-30LX-EW's 40 scans a
second, 24 000 scans; `ramp sim mission` must finish it with everything else in well under
30 s of wall time. Measured in this process (no sockets), each figure beside a baseline in
the same run:

- `world_step_us`: `MarteWorld.step(0.01)` in a seeded arena (rocks, craters, undulating
  ground), the robot driving a weave that meets walls and obstacles; baseline: the same
  script in the empty, level arena (the physics model before the arena was added).
- `scan_*_us`: `LidarView.scan` of 1081 steps from a robot creeping 1 mm a scan (so every
  scan is cast anew): level, tilted 20 deg down, tilted with the gimbal moving too (the view
  of the robot's own frame comes from its per-angle memory after the first pass), and
  standing still (the same pose again: only noise and dust are drawn); baseline: one numpy
  pass over 1081 elements (`np.hypot`), i.e. the per-call floor of numpy here.

Times are per call, from batches timed with `time.perf_counter` (median and worst batch).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bench.common import Settings, compare, progress
from firmware_like.lidar_view import LidarView
from firmware_like.marte import MarteWorld

# (batches, calls per batch) of world steps and of scans, per profile.
_COUNTS = {"full": (40, 1000, 40, 200), "quick": (10, 500, 10, 100), "smoke": (2, 50, 2, 10)}
MISSION_STEPS = 60_000  # 600 s at 100 Hz
MISSION_SCANS = 24_000  # 600 s at 40 scans/s


def _per_call_us(fn: Callable[[], Any], batches: int, calls: int) -> dict[str, float]:
    fn()  # warm up (imports, caches)
    times = []
    for _ in range(batches):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        times.append((time.perf_counter() - t0) / calls * 1e6)
    times.sort()
    return {"p50": round(times[len(times) // 2], 1), "max": round(times[-1], 1)}


def _weave(world: MarteWorld) -> Callable[[], None]:
    """A driving script: full ahead with a slow left-right weave, reversing every 20 s."""
    state = {"n": 0}

    def step() -> None:
        n = state["n"]
        state["n"] = n + 1
        t = n * 0.01
        sign = 1.0 if int(t // 20) % 2 == 0 else -1.0
        turn = 0.4 * math.sin(t * 0.7)
        world.set_motor("base.lf_wheel", sign * (0.8 - turn))
        world.set_motor("base.lb_wheel", sign * (0.8 - turn))
        world.set_motor("base.rf_wheel", -sign * (0.8 + turn))
        world.set_motor("base.rb_wheel", -sign * (0.8 + turn))
        world.step(0.01)

    return step


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    step_batches, step_calls, scan_batches, scan_calls = _COUNTS[settings.profile]
    progress(f"arena: {step_batches} x {step_calls} world steps, {scan_batches} x {scan_calls} "
             "scans per case")
    arena_world = MarteWorld.seeded(7)
    arena_world.place(1.5, 1.2, 15.0)
    empty_world = MarteWorld()
    step = _per_call_us(_weave(arena_world), step_batches, step_calls)
    base = _per_call_us(_weave(empty_world), step_batches, step_calls)
    meetings = {"collisions": arena_world.collisions, "crater_entries": arena_world.crater_entries}

    world = MarteWorld.seeded(7)
    view = LidarView.of(world)

    def poses(tilt_deg: float, tilt_step_deg: float = 0.0) -> list[Any]:
        """64 poses of a robot creeping forward 1 mm a scan (each scan casts anew)."""
        out = []
        for k in range(64):
            world.place(1.2 + 0.001 * k, 1.94, 0.0)
            out.append(view.pose_of_world(0.0, math.radians(tilt_deg + tilt_step_deg * k)))
        return out

    def cycle(seq: list[Any]) -> Callable[[], None]:
        turn = {"k": 0}

        def scan() -> None:
            turn["k"] = (turn["k"] + 1) % len(seq)
            view.scan(seq[turn["k"]])

        return scan

    level, tilted, tilting = poses(0.0), poses(20.0), poses(18.0, 0.01)
    a, b = np.random.default_rng(0).random((2, 1081))
    baseline = _per_call_us(lambda: np.hypot(a, b), scan_batches, scan_calls * 10)
    scans = {
        "level": _per_call_us(cycle(level), scan_batches, scan_calls),
        "tilted": _per_call_us(cycle(tilted), scan_batches, scan_calls),
        "tilted_gimbal_moving": _per_call_us(cycle(tilting), scan_batches, scan_calls),
        "standing_still": _per_call_us(lambda: view.scan(tilted[0]), scan_batches, scan_calls),
    }
    hits = {name: int((view.scan(seq[0], noise=False).kinds > 0).sum())
            for name, seq in (("level", level), ("tilted", tilted))}
    mission_s = (MISSION_STEPS * step["p50"] + MISSION_SCANS * scans["tilted_gimbal_moving"][
        "p50"]) / 1e6
    return {
        "world_step_us": {k: compare(step[k], base[k]) for k in ("p50", "max")},
        "world_meetings": meetings,
        "scan_level_us": {k: compare(scans["level"][k], baseline[k]) for k in ("p50", "max")},
        "scan_tilted_us": {k: compare(scans["tilted"][k], baseline[k]) for k in ("p50", "max")},
        "scan_tilted_gimbal_moving_us": {
            k: compare(scans["tilted_gimbal_moving"][k], baseline[k]) for k in ("p50", "max")},
        "scan_standing_still_us": {
            k: compare(scans["standing_still"][k], baseline[k]) for k in ("p50", "max")},
        "beams_with_echo": hits,
        "mission_world_and_lidar_cpu_s": round(mission_s, 2),
    }
