"""`perception`: the CPU cost of the integrated chain, as `ramp sim perceive` and the mission
run it: one localization, one full 3D scan, one detection, one whole flow.

Each layout is a seeded SPEC 6.1 arena with the robot at the start region's front edge facing
the obstacle region (where the mission scans from). On the rig (world, Hokuyo emulator over
SCIP/TCP to the real driver, IMU and servo emulators behind the `sim` drivers, AHRS, gimbal,
scan records), in this process, each figure beside a baseline measured in the same run:

- `localize_ms`: `pipeline.localize` on the 10 level scans the rig recorded (fusing them beam
  by beam, line extraction, candidates, refinement, the tilt check); baseline: one
  `np.linalg.lstsq` straight-line fit through the fused scan's points.
- `sweep`: the stop-and-go 3D scan (`pipeline.plan_scan` + `sweep.Sweep`, ~80 tilts):
  simulated seconds (the gimbal's and the LIDAR's time: what the robot waits) and CPU
  seconds (`time.process_time`) of the rig while it runs; baseline: `world.step` alone for
  the same simulated time (the floor any simulation of it pays). On the robot the emulators'
  share (the ray-casting, most of it) is not spent.
- `detect_ms`: `pipeline.detect` (merge + obstacle detection) on the sweep's records; baseline:
  a least-squares plane through the same merged cloud.
- `flow`: the whole `perceive()` (settle, localize, sweep, level check, detect): simulated and
  CPU seconds, and the localizer's and the detector's share of it.

Times are per call (median and worst over layouts and repeats).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bench.common import Settings, compare, progress
from firmware_like.marte import MarteWorld
from ramp.autonomy.perception import pipeline
from ramp.autonomy.perception.cloud import merge
from ramp.autonomy.perception.obstacles import fit_plane_lsq
from ramp.autonomy.perception.sweep import DONE, Sweep
from ramp.simulation.perceive import perceive
from ramp.simulation.rig import Rig, load_autonomy_config

_COUNTS = {"full": (8, 5), "quick": (2, 2), "smoke": (1, 1)}  # layouts, repeats
X, YAW = 0.88, 0.0


def _ms(fn: Callable[[], Any], repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def _stats(values: list[float], digits: int = 2) -> dict[str, float]:
    v = sorted(values)
    return {"p50": round(v[len(v) // 2], digits), "max": round(v[-1], digits)}


def _world(seed: int) -> tuple[MarteWorld, str]:
    world = MarteWorld.seeded(seed)
    y = 1.94 + (0.25 if seed % 2 else -0.25)
    world.place(X, y, YAW)
    return world, "left" if y >= 1.94 else "right"


def _sweep_cost(seed: int) -> tuple[float, float, int]:
    """(simulated s, CPU s, scans) of one 3D scan on a settled rig."""
    world, _ = _world(seed)
    config = load_autonomy_config()
    with Rig(world, config, seed=seed) as rig:
        rig.run_until(lambda: rig.perception.ready, 10.0)
        plan = pipeline.plan_scan(config, pipeline.PoseEstimate(world.x, world.y, world.yaw))
        assert plan is not None
        sweep = Sweep(rig.leveller, rig.scans, rig.pan_tilt, plan, ahrs=rig.ahrs)
        task = rig.scheduler.add_task("sweep", rig.scheduler.rate_hz, sweep.tick)
        t0, cpu0 = rig.clock.now(), time.process_time()
        sweep.start(t0)
        rig.run_until(lambda: sweep.finished, 2.0 * plan.duration_s + 10.0)
        cpu = time.process_time() - cpu0
        sim = rig.clock.now() - t0
        rig.scheduler.remove_task(task)
        if sweep.state != DONE:
            raise RuntimeError(f"the sweep failed: {sweep.reason}")
        return sim, cpu, len(sweep.records)


def _world_step_cpu(sim_s: float) -> float:
    world, _ = _world(0)
    cpu0 = time.process_time()
    for _ in range(round(sim_s / 0.01)):
        world.step(0.01)
    return time.process_time() - cpu0


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    layouts, repeats = _COUNTS[settings.profile]
    progress(f"perception: {layouts} layouts through the rig, {repeats} repeats of each call")
    config = load_autonomy_config()
    loc_ms: list[float] = []
    line_ms: list[float] = []
    det_ms: list[float] = []
    plane_ms: list[float] = []
    flow_sim: list[float] = []
    flow_cpu: list[float] = []
    flow_loc: list[float] = []
    flow_det: list[float] = []
    sweep_sim: list[float] = []
    sweep_cpu: list[float] = []
    step_cpu: list[float] = []
    scans = points = 0
    for seed in range(layouts):
        world, box = _world(seed)
        cpu0 = time.process_time()
        result = perceive(world, config, seed=seed, hint=box)
        flow_cpu.append(time.process_time() - cpu0)
        flow_sim.append(result.sim_time_s)
        flow_loc.append(result.cpu_localize_s)
        flow_det.append(result.cpu_detect_s)
        pose = result.pose
        if pose is None:
            raise RuntimeError(f"layout {seed}: lost ({result.localization.reason})")
        level, swept = result.level_records, result.sweep_records
        fused = pipeline.fuse_scans(level)[0].points_level()
        design = np.column_stack((fused[:, 0], np.ones(fused.shape[0])))
        loc_ms += _ms(lambda lv=level, b=box: pipeline.localize(lv, hint=b), repeats)
        line_ms += _ms(lambda a=design, z=fused: np.linalg.lstsq(a, z[:, 1], rcond=None),
                       repeats)
        cloud = merge(swept, pose.x, pose.y, pose.yaw)
        scans, points = len(swept), len(cloud)
        det_ms += _ms(lambda s=swept, p=pose: pipeline.detect(s, p), repeats)
        plane_ms += _ms(lambda c=cloud: fit_plane_lsq(c.points), repeats)
        sim, cpu, _ = _sweep_cost(seed)
        sweep_sim.append(sim)
        sweep_cpu.append(cpu)
        step_cpu.append(_world_step_cpu(sim))
    loc, line = _stats(loc_ms), _stats(line_ms, 3)
    det, plane = _stats(det_ms), _stats(plane_ms)
    sw_cpu, st_cpu = _stats(sweep_cpu, 3), _stats(step_cpu, 3)
    med = lambda v: round(float(np.median(v)), 3)  # noqa: E731
    return {
        "layouts": layouts,
        "sweep_scans": scans,
        "cloud_points": points,
        "localize_ms": {k: compare(loc[k], line[k]) for k in ("p50", "max")},
        "sweep": {"simulated_s": _stats(sweep_sim),
                  "cpu_s": {k: compare(sw_cpu[k], st_cpu[k]) for k in ("p50", "max")}},
        "detect_ms": {k: compare(det[k], plane[k]) for k in ("p50", "max")},
        "scan_cpu_ms_per_tilt": round(sw_cpu["p50"] / max(scans, 1) * 1e3, 2),
        "scan_and_detect_cpu_s": round(sw_cpu["p50"] + det["p50"] / 1e3, 3),
        "flow": {"simulated_s": med(flow_sim), "cpu_s": med(flow_cpu),
                 "localize_cpu_s": med(flow_loc), "detect_cpu_s": med(flow_det),
                 "simulated_s_per_cpu_s": round(float(np.median(flow_sim)) / max(
                     float(np.median(flow_cpu)), 1e-9), 1)},
        "note": ("the sweep's CPU includes the simulator (ray-casting, SCIP encoding); on the "
                 "robot only the drivers, the records and the detection remain"),
    }
