"""`obstacles`: CPU cost of one 3D scan's merge and obstacle detection, in this process.

The mission stops, sweeps the gimbal (about 80 scans, `SweepPlan.duration_s` ~13 s) and then
needs the obstacles before it plans; the detector must cost little beside that. Each layout
is a seeded SPEC 6.1 arena scanned from the start region (`tests/obstacle_scenes.py`, the
same scenes as the tests); the records are made once, then timed:

- `merge_ms`: `cloud.merge` of the sweep's records into one arena-frame cloud;
- `detect_ms`: `obstacles.detect_obstacles` on that cloud (walls, ground, levelling, runs,
  clusters, fits);
- `merge_and_detect_ms` beside the baseline `lsq_plane_ms`: a plain least-squares plane
  through every point of the same cloud, the least any ground-based detector does (one
  pass of linear algebra over the cloud); `ransac_plane_ms` for context.

Times are per call (`time.perf_counter`), median and worst over layouts and repeats. The
accuracy on the same layouts is reported beside them (worst position and diameter errors of
obstacles of 15 cm or more, false obstacles per layout, and by distance from the scanner):
not a speed, but what the time buys.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bench.common import Settings, compare, progress
from firmware_like.marte import MarteWorld
from ramp.autonomy.perception.cloud import merge
from ramp.autonomy.perception.obstacles import (
    detect_obstacles,
    fit_plane_lsq,
    fit_plane_ransac,
)
from tests.obstacle_scenes import match, scan_world

_COUNTS = {"full": (12, 5), "quick": (3, 2), "smoke": (1, 1)}  # layouts, repeats
_BANDS = ((0.0, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 4.0))
X, Y, YAW = 0.9, 1.94, 0.0  # the robot at the start region's front edge, facing +x


def _timed(fn: Callable[[], Any], repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def _stats(ms: list[float]) -> dict[str, float]:
    ms = sorted(ms)
    return {"p50": round(ms[len(ms) // 2], 2), "max": round(ms[-1], 2)}


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    layouts, repeats = _COUNTS[settings.profile]
    progress(f"obstacles: {layouts} layouts x {repeats} repeats")
    times: dict[str, list[float]] = {k: [] for k in ("merge", "detect", "both", "lsq",
                                                     "ransac")}
    points = scans = 0
    sweep_s = 0.0
    required = found = false = 0
    worst_pos = worst_d = 0.0
    bands: dict[str, list[tuple[float, float]]] = {f"{a:g}-{b:g} m": [] for a, b in _BANDS}
    for seed in range(layouts):
        scene = scan_world(MarteWorld.seeded(seed), X, Y, YAW, seed=seed)
        records = scene.records
        cloud = merge(records, X, Y, YAW)
        points, scans, sweep_s = len(cloud), len(records), scene.plan.duration_s
        detect_obstacles(cloud)  # warm up
        times["merge"] += _timed(lambda r=records: merge(r, X, Y, YAW), repeats)
        times["detect"] += _timed(lambda c=cloud: detect_obstacles(c), repeats)
        times["both"] += _timed(lambda r=records: detect_obstacles(merge(r, X, Y, YAW)),
                                repeats)
        times["lsq"] += _timed(lambda c=cloud: fit_plane_lsq(c.points), repeats)
        times["ransac"] += _timed(lambda c=cloud: fit_plane_ransac(c.points), repeats)
        matches, left = match(scene, detect_obstacles(cloud).obstacles)
        false += len(left)
        for m in matches:
            if m.truth["d"] < 0.15:
                continue
            required += 1
            if m.found is None or m.found.kind != m.kind:
                continue
            found += 1
            worst_pos = max(worst_pos, m.position_error)
            worst_d = max(worst_d, abs(m.diameter_error))
            for (a, b), name in zip(_BANDS, bands, strict=True):
                if a <= m.distance_m < b:
                    bands[name].append((m.position_error, m.diameter_error))
    stats = {k: _stats(v) for k, v in times.items()}
    return {
        "layouts": layouts,
        "cloud_points": points,
        "scans": scans,
        "sweep_duration_s": round(sweep_s, 2),
        "merge_ms": stats["merge"],
        "detect_ms": stats["detect"],
        "merge_and_detect_ms": {k: compare(stats["both"][k], stats["lsq"][k])
                                for k in ("p50", "max")},
        "lsq_plane_ms": stats["lsq"],
        "ransac_plane_ms": stats["ransac"],
        "accuracy": {
            "required": required, "found": found, "false_per_layout": round(
                false / layouts, 2),
            "worst_position_cm": round(worst_pos * 100, 1),
            "worst_diameter_cm": round(worst_d * 100, 1),
            "by_distance": {
                name: {"n": len(v),
                       "worst_position_cm": round(max(p for p, _ in v) * 100, 1),
                       "worst_diameter_cm": round(max(abs(d) for _, d in v) * 100, 1),
                       "mean_diameter_cm": round(float(np.mean([d for _, d in v])) * 100, 1)}
                for name, v in bands.items() if v},
        },
        "steepest_tilt_deg": scene.plan.tilts_deg[-1],
    }
