"""`rig`: how fast the simulation rig runs, in simulated seconds per wall second.

`ramp sim mission` (SPEC 6.3) must run at 50x real time or more. The rig (`ramp/simulation/
rig.py`) runs, on one virtual clock and one scheduler at 100 Hz: the world, the Hokuyo
emulator ray-casting 40 scans a second and serving them as SCIP over loopback TCP to the real
driver, the IMU emulator at 125 samples a second, the gimbal emulator, and the autonomy's
perception tasks (odometry, AHRS, scan records, gimbal levelling). Figures from a
robot driving a weave in a seeded arena (so every scan is cast anew), in this process:

- `sensors`: the rig, world stepped by the rig; baseline: `world.step(0.01)` alone on the
  same script (the floor any simulation of this world pays), measured in the same run;
- `sensors_scans_on_demand`: the same, but the LIDAR asked for a scan (GD) 4 times a
  second instead of streaming all 40 (what a mission localizing every 0.25 s needs);
- `with_backend`: the streaming rig plus the backend (a real `Supervisor` with the sim
  backplane, the Sabertooth emulators behind ptys, MCP over loopback TCP) driven by the
  autonomy's `McpLink`, which is what a mission runs; same baseline.

Real-time factor = simulated seconds / wall seconds (`time.perf_counter`); CPU seconds per
simulated minute (`time.process_time`) too, since a busy machine stretches wall time only.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench.common import Settings, compare, progress
from firmware_like.marte import MarteWorld
from ramp.autonomy.mcp_link import McpLink
from ramp.simulation.backend import SimBackend
from ramp.simulation.rig import Rig

SIM_SECONDS = {"full": 120.0, "quick": 30.0, "smoke": 2.0}
SEED = 7
ON_DEMAND_HZ = 4.0  # scans a second a mission asks for while it drives (one every 0.25 s)


def _duties(t: float) -> tuple[float, float]:
    """(left, right) duty of a slow weave at about half speed, reversing every 20 s."""
    sign = 1.0 if int(t // 20) % 2 == 0 else -1.0
    turn = 0.3 * math.sin(t * 0.7)
    return sign * (0.5 - turn), sign * (0.5 + turn)


def _drive(world: MarteWorld, t: float) -> None:
    left, right = _duties(t)
    for name in ("base.lf_wheel", "base.lb_wheel"):
        world.set_motor(name, left)
    for name in ("base.rf_wheel", "base.rb_wheel"):
        world.set_motor(name, -right)


def _world() -> MarteWorld:
    world = MarteWorld.seeded(SEED)
    world.place(2.0, 1.94, 0.0)
    return world


def _timed(fn: Callable[[], None], sim_s: float) -> dict[str, float]:
    wall0, cpu0 = time.perf_counter(), time.process_time()
    fn()
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return {"wall_s": wall, "cpu_s": cpu, "rtf": sim_s / wall,
            "cpu_s_per_sim_min": cpu / sim_s * 60.0}


def _baseline(sim_s: float) -> dict[str, float]:
    world = _world()

    def go() -> None:
        for k in range(round(sim_s / 0.01)):
            _drive(world, k * 0.01)
            world.step(0.01)

    return _timed(go, sim_s)


def _sensors(sim_s: float) -> tuple[dict[str, float], dict[str, Any]]:
    world = _world()
    with Rig(world, seed=SEED) as rig:
        rig.run_until(lambda: rig.perception.ready, 5.0)
        scans0 = rig.lidar.stats["scans"]
        rig.scheduler.add_task("drive", rig.scheduler.rate_hz,
                               lambda now, dt: _drive(world, rig.time))
        fig = _timed(lambda: rig.run_for(sim_s), sim_s)
        counts = {"scans": rig.lidar.stats["scans"] - scans0, "imu_samples": rig.ahrs.samples,
                  "ahrs_settled": rig.ahrs.settled}
    return fig, counts


def _on_demand(sim_s: float, rate_hz: float) -> tuple[dict[str, float], dict[str, Any]]:
    """The rig with the LIDAR asked for a scan (GD) `rate_hz` times a second instead of
    streaming all 40: what a mission that localizes every 0.25 s while it drives needs."""
    world = _world()
    with Rig(world, seed=SEED, stream=False) as rig:
        rig.run_until(lambda: rig.perception.ready, 5.0)
        scans0 = rig.lidar.stats["scans"]
        rig.scheduler.add_task("drive", rig.scheduler.rate_hz,
                               lambda now, dt: _drive(world, rig.time))
        rig.scheduler.add_task("ask", rate_hz, lambda now, dt: rig.lidar.request_scan())
        fig = _timed(lambda: rig.run_for(sim_s), sim_s)
        counts = {"scans": rig.lidar.stats["scans"] - scans0, "scans_per_s": rate_hz}
    return fig, counts


def _with_backend(sim_s: float) -> tuple[dict[str, float], dict[str, Any]]:
    world = _world()
    backend = SimBackend(world)
    with Rig(world, seed=SEED, backend=backend) as rig:
        link = McpLink(backend.address, clock=rig.clock, loop=rig.scheduler,
                       on_connect=lambda ln: ln.send("robot:control.acquire=(autonomy)"))
        rig.scheduler.add_task("autonomy.mcp", rig.scheduler.rate_hz, link.tick)
        link.start()
        rig.run_until(lambda: rig.perception.ready and link.connected, 5.0)
        scans0 = rig.lidar.stats["scans"]
        last: list[tuple[int, float]] = []

        def drive(now: float, dt: float) -> None:  # a drive command every 0.1 s
            left, right = _duties(rig.time)
            speed = round(100 * max(abs(left), abs(right)))
            direction = math.degrees(math.atan2(left - right, left + right))
            cmd = (speed, round(direction))
            if not last or last[-1] != cmd:
                link.send(f"base:base.drive=({cmd[0]},{cmd[1]})")
                last.append(cmd)

        rig.scheduler.add_task("drive", 10.0, drive)
        fig = _timed(lambda: rig.run_for(sim_s), sim_s)
        counts = {"scans": rig.lidar.stats["scans"] - scans0, "commands": len(last),
                  "mcp_replies": link.stats["replies"], "moved_m": round(world.x - 2.0, 3)}
        link.stop()
    return fig, counts


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    sim_s = SIM_SECONDS.get(settings.profile, 30.0)
    progress(f"rig: world.step alone, {sim_s:g} simulated s")
    base = _baseline(sim_s)
    progress(f"rig: world, emulators, drivers and perception, {sim_s:g} simulated s")
    sensors, sensor_counts = _sensors(sim_s)
    progress(f"rig: the same, scans on demand at {ON_DEMAND_HZ:g} Hz")
    demand, demand_counts = _on_demand(sim_s, ON_DEMAND_HZ)
    progress(f"rig: the same with the backend over MCP, {sim_s:g} simulated s")
    backend, backend_counts = _with_backend(sim_s)

    def fig(f: dict[str, float]) -> dict[str, Any]:
        return {"real_time_factor": compare(round(f["rtf"], 1), round(base["rtf"], 1)),
                "cpu_s_per_simulated_minute": compare(round(f["cpu_s_per_sim_min"], 3),
                                                      round(base["cpu_s_per_sim_min"], 3)),
                "wall_s": round(f["wall_s"], 3)}

    return {"simulated_s": sim_s, "tick_hz": 100,
            "sensors": {**fig(sensors), **sensor_counts},
            "sensors_scans_on_demand": {**fig(demand), **demand_counts},
            "with_backend": {**fig(backend), **backend_counts}}
