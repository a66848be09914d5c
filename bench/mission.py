"""`mission`: a whole `ramp sim mission` run, in simulated seconds per wall second.

SPEC 6.3 / issue 11: a 10-minute mission in well under 30 s of wall time on one core, i.e. a
real-time factor well over 20. The run is `ramp.simulation.mission.MissionRun` on the default
seed: the world, the backend (a real `Supervisor`, its Sabertooths behind ptys), the Hokuyo
emulator over SCIP/TCP, the IMU and gimbal emulators, the autonomy's drivers, perception, the
executive and the mission machine over MCP/TCP, all on one virtual clock. Baseline, in the
same run: `world.step(0.01)` alone over the same simulated time with the robot driving (the
floor any simulation of this world pays).

The mission and its baseline run three times in turn (the `full` profile) and the figures are
the medians, each run's factors listed beside them: this kind of shared machine moves by more
between two runs than most changes to the code do.

Beside the factor: CPU seconds per simulated minute, and where the time went, by scheduler
task (the tasks' own time, summed by part: the world and backend, the simulated sensors, the
autonomy's drivers and perception, the executive and mission, and the I/O between ticks),
measured in a second run of the same mission: timing every task slows the run it times.
"""

from __future__ import annotations

import math
import statistics
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

from bench.common import Settings, compare, progress
from firmware_like.marte import MarteWorld
from ramp.common import accel
from ramp.simulation.campaign import combination
from ramp.simulation.mission import MissionOptions, MissionRun

SIM_SECONDS = {"full": 600.0, "quick": 120.0, "smoke": 12.0}
#: Untimed missions, each after its own `world.step` baseline: the figures are their medians,
#: since this kind of machine moves by more between two runs than most changes do.
REPEATS = {"full": 3, "quick": 1, "smoke": 1}
SEED = 0

#: Scheduler task name prefixes -> the part of the run they belong to.
PARTS = (("sim.lidar", "simulated LIDAR (ray-cast, SCIP encode)"),
         ("sim.", "simulated world and trace"),
         ("autonomy.lidar", "autonomy LIDAR driver (SCIP decode)"),
         ("autonomy.imu", "autonomy IMU driver"),
         ("autonomy.ahrs", "AHRS"),
         ("autonomy.scans", "scan records"),
         ("autonomy.gimbal", "gimbal"),
         ("autonomy.odometry", "odometry"),
         ("autonomy.mcp", "autonomy MCP link"),
         ("autonomy.poll", "autonomy MCP link"),
         ("autonomy.pose", "executive (pose tracker)"),
         ("mission", "executive and mission (localizing, planning, detecting included)"))


def _part(task: str) -> str:
    for prefix, part in PARTS:
        if task.startswith(prefix):
            return part
    return "backend (supervisor, buses, emulated controllers)"


def _time_tasks(mission: MissionRun) -> dict[str, float]:
    """Wrap every scheduler task of the run so its wall time is summed by name (the
    scheduler's own task times are on the virtual clock, which does not move inside a
    tick)."""
    assert mission.rig is not None
    spent: dict[str, float] = defaultdict(float)
    for task in mission.rig.scheduler.tasks:
        def timed(now: float, dt: float, fn: Any = task.fn, name: str = task.name) -> None:
            t0 = time.perf_counter()
            try:
                fn(now, dt)
            finally:
                spent[name] += time.perf_counter() - t0
        task.fn = timed
    return spent


def _baseline(sim_s: float) -> dict[str, float]:
    world = MarteWorld.seeded(SEED)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(round(sim_s / 0.01)):
        t = k * 0.01
        turn = 0.3 * math.sin(t * 0.7)
        for name in ("base.lf_wheel", "base.lb_wheel"):
            world.set_motor(name, 0.5 - turn)
        for name in ("base.rf_wheel", "base.rb_wheel"):
            world.set_motor(name, -(0.5 + turn))
        world.step(0.01)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return {"rtf": sim_s / wall, "cpu_s_per_sim_min": cpu / sim_s * 60.0}


def _mission(sim_s: float) -> MissionRun:
    box, heading = combination(SEED)
    mission = MissionRun(MissionOptions(seed=SEED, start_box=box, heading=heading,
                                        duration=sim_s))
    mission.build()
    return mission


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    sim_s = SIM_SECONDS.get(settings.profile, 120.0)
    box, heading = combination(SEED)
    # The factor comes from runs with nothing added to them: timing every task costs a
    # wrapper call per task per tick, so the time by part comes from one more run of the same
    # mission with the tasks timed.
    bases: list[dict[str, float]] = []
    runs: list[tuple[float, float, dict[str, Any]]] = []  # (factor, CPU s, summary)
    repeats = REPEATS.get(settings.profile, 1)
    for k in range(repeats):
        progress(f"mission {k + 1}/{repeats}: world.step alone, {sim_s:g} simulated s")
        bases.append(_baseline(sim_s))
        progress(f"mission {k + 1}/{repeats}: seed {SEED} ({box} box, heading {heading}), "
                 f"{sim_s:g} simulated s")
        mission = _mission(sim_s)
        cpu0 = time.process_time()
        summary = mission.run()
        cpu = time.process_time() - cpu0
        runs.append((max(summary["sim_time_s"], 1e-9) / summary["wall_time_s"], cpu, summary))
    rtf, cpu, summary = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
    base = {key: statistics.median(b[key] for b in bases) for key in bases[0]}
    sim = max(summary["sim_time_s"], 1e-9)
    progress("mission: the same run again, every task timed")
    timed = _mission(sim_s)
    spent = _time_tasks(timed)
    timed_summary = timed.run()
    by_part: dict[str, float] = defaultdict(float)
    total = 0.0
    for name, seconds in spent.items():
        by_part[_part(name)] += seconds
        total += seconds
    wall = timed_summary["wall_time_s"]
    parts = {name: round(100.0 * s / wall, 1) for name, s in sorted(
        by_part.items(), key=lambda kv: -kv[1])}
    parts["I/O between ticks and the rest"] = round(100.0 * max(0.0, wall - total) / wall, 1)
    return {
        "simulated_s": round(sim, 1),
        "real_time_factor": compare(round(rtf, 1), round(base["rtf"], 1)),
        "real_time_factors": [round(r[0], 1) for r in runs],
        "world_step_factors": [round(b["rtf"], 1) for b in bases],
        "cpu_s_per_simulated_minute": compare(round(cpu / sim * 60.0, 3),
                                              round(base["cpu_s_per_sim_min"], 3)),
        "wall_s": round(summary["wall_time_s"], 2),
        "compiled_hot_path": accel.status().active or accel.status().reason,
        "ten_minutes_wall_s": round(600.0 / rtf, 1),
        "timed_run_real_time_factor": round(sim / max(wall, 1e-9), 1),
        "wall_pct_by_part": parts,
        "outcome": summary["outcome"], "final_state": summary["final_state"],
        "delivered_kg": summary["delivered_kg"], "collisions": summary["collisions"],
        "crater_entries": summary["crater_entries"],
    }
