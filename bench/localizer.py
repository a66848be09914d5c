"""`localizer`: CPU cost of one wall-based localization, in this process.

The mission localizes after every leg it drives, and more often while it tracks a path; a
localization must cost little beside the 25 ms the UTM-30LX-EW takes per scan. Measured on
scans of the simulated arena as the autonomy records them (1081 beams, the robot's frame
posts and dust in them), each figure beside a baseline in the same run:

- `localize_us`: `localize(record, hint=...)`: wall points, line extraction, candidate poses,
  Gauss-Newton refinement of each, scoring, the tilt check; a level scan, no fault.
- `track_us`: `localize` with the odometry prior and the AHRS yaw (what `Localizer.update`
  does between scans).
- `extract_us`: `extract_lines` alone on the same wall points.
- `relevel_us`: a scan tipped 4-8 deg by a wrong attitude, localized with the odometry
  prior: `localize` detects it, searches the tilt (`relevel`) and localizes the re-levelled
  scan. This is the recovery path, run only when a scan looks tilted.
- baseline: one `np.linalg.lstsq` straight-line fit (y = a x + b) of the same wall points,
  i.e. the least a line-based localizer must do with them.

Times are per call from batches timed with `time.perf_counter` (median and worst batch).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bench.common import Settings, compare, progress
from firmware_like.arena_params import LidarParams
from firmware_like.lidar_view import LidarView
from firmware_like.marte import MarteWorld
from ramp.autonomy.mount import Mount, lidar_pose
from ramp.autonomy.perception.lines import extract_lines
from ramp.autonomy.perception.localizer import Pose, PosePrior, localize, wall_points
from ramp.autonomy.perception.records import ScanRecord

# (batches, calls per batch) for the cheap figures; scans in the tilted set.
_COUNTS = {"full": (20, 40, 24), "quick": (6, 20, 8), "smoke": (2, 4, 2)}


def _record(world: MarteWorld, view: LidarView, roll_error: float = 0.0,
            pitch_error: float = 0.0) -> ScanRecord:
    """A scan levelled by the gimbal against the AHRS's belief (truth + error)."""
    lp = LidarParams()
    mount = Mount(lp.mount_x, lp.mount_y, lp.mount_z)
    c = world.chassis_pose()
    roll_b, pitch_b = c.roll + roll_error, c.pitch + pitch_error
    scan = view.scan(view.pose(c.x, c.y, c.z, c.roll, c.pitch, c.yaw, 0.0, -pitch_b))
    pos, rot = lidar_pose(mount, mount.position, 0.0, math.degrees(-pitch_b))
    return ScanRecord(0.0, scan.ranges, view.angles, pos, rot, roll_b, pitch_b, c.yaw)


def _per_call_us(fn: Callable[[], Any], batches: int, calls: int) -> dict[str, float]:
    fn()  # warm up
    times = []
    for _ in range(batches):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        times.append((time.perf_counter() - t0) / calls * 1e6)
    times.sort()
    return {"p50": round(times[len(times) // 2], 1), "max": round(times[-1], 1)}


def _cycle(items: list[Any], fn: Callable[[Any], Any]) -> Callable[[], None]:
    turn = {"k": 0}

    def call() -> None:
        turn["k"] = (turn["k"] + 1) % len(items)
        fn(items[turn["k"]])

    return call


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    batches, calls, tilted_n = _COUNTS[settings.profile]
    progress(f"localizer: {batches} x {calls} localizations per case, {tilted_n} tilted scans")
    level: list[tuple[ScanRecord, str]] = []
    for k in range(8):
        box = ("left", "right")[k % 2]
        world = MarteWorld.seeded(k, box, (0, 90, 180, 270)[k // 2])
        level.append((_record(world, LidarView.of(world)), box))
    rng = np.random.default_rng(7)
    tracked: list[tuple[ScanRecord, PosePrior]] = []
    tilted: list[tuple[ScanRecord, PosePrior]] = []
    for k in range(max(8, tilted_n)):
        world = MarteWorld.seeded(k)
        while True:  # not on a rock: a leaning chassis makes any scan look tilted
            world.place(rng.uniform(1.5, 5.8), rng.uniform(1.0, 2.9), rng.uniform(-180, 180))
            if max(abs(world.roll), abs(world.pitch)) < math.radians(3.0):
                break
        view = LidarView.of(world)
        cov = np.diag((0.05 ** 2, 0.05 ** 2, math.radians(2.0) ** 2))
        tracked.append((_record(world, view), PosePrior(Pose(world.x + 0.02, world.y - 0.02,
                                                             world.yaw + 0.01), cov)))
        if k < tilted_n:
            mag, axis = math.radians(rng.uniform(4, 8)), rng.uniform(0, 2 * math.pi)
            tilted.append((_record(world, view, mag * math.cos(axis), mag * math.sin(axis)),
                           tracked[-1][1]))

    points = [wall_points(rec) for rec, _ in level]
    lines = [(p.xy[:, 0], p.xy[:, 1]) for p in points]
    design = [np.column_stack((x, np.ones_like(x))) for x, _ in lines]

    def lstsq(i: int) -> None:
        np.linalg.lstsq(design[i], lines[i][1], rcond=None)

    baseline = _per_call_us(_cycle(list(range(len(lines))), lstsq), batches, calls * 10)
    loc = _per_call_us(_cycle(level, lambda rb: localize(rb[0], hint=rb[1])), batches, calls)
    track = _per_call_us(_cycle(tracked, lambda rp: localize(rp[0], yaw_prior=rp[0].yaw,
                                                             prior=rp[1])), batches, calls)
    extract = _per_call_us(_cycle(points, lambda p: extract_lines(p.xy, p.beams, p.sensor)),
                           batches, calls)
    outcomes = {"relevelled": 0, "lost": 0, "kept": 0}
    times = []
    for rec, prior in tilted:
        t0 = time.perf_counter()
        res = localize(rec, yaw_prior=rec.yaw, prior=prior)
        times.append((time.perf_counter() - t0) * 1e6)
        if res.relevel is not None and res.relevel.found and not res.lost:
            outcomes["relevelled"] += 1
        elif res.lost:
            outcomes["lost"] += 1
        else:
            outcomes["kept"] += 1
    times.sort()
    relevel = {"p50": round(times[len(times) // 2], 1), "max": round(times[-1], 1)}
    return {
        "wall_points": int(np.median([p.xy.shape[0] for p in points])),
        "localize_us": {k: compare(loc[k], baseline[k]) for k in ("p50", "max")},
        "track_us": {k: compare(track[k], baseline[k]) for k in ("p50", "max")},
        "extract_us": {k: compare(extract[k], baseline[k]) for k in ("p50", "max")},
        "relevel_us": {k: compare(relevel[k], baseline[k]) for k in ("p50", "max")},
        "tilted_scans": len(tilted),
        "tilted_outcomes": outcomes,
    }
