"""`autonomy_sensors`: CPU cost of the IMU and gimbal emulators, in this process.

The mission runs at 50x real time or more (SPEC 6.3, `ramp sim mission`), so the emulators of
the autonomy's sensors must cost little per simulated second. The IMU emulator produces one
SpatialData sample every 8 ms of simulated time from the chassis truth (interpolation, mount
rotation, lever arm, noise, bias, faults); the gimbal emulator integrates two servos. Both are
polled every 10 ms of virtual time, as the scheduler's 100 Hz tick would. The baseline is the
least any emulator must do per sample: take 6 normals from a pre-drawn block and build two
3-tuples, in the same loop shape.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.common import Settings, compare, progress
from firmware_like.imu import ImuEmulator, ImuTruth
from firmware_like.servo import PanTiltEmulator, ServoEmulator
from ramp.clock import VirtualClock

SIM_SECONDS = {"full": 600.0, "quick": 60.0, "smoke": 2.0}
TICK_S = 0.01
INTERVAL_MS = 8


def _imu(sim_s: float, fault: str) -> tuple[float, int]:
    clock = VirtualClock()
    state = {"i": 0}

    def truth() -> ImuTruth:
        state["i"] += 1
        a = 0.002 * state["i"]
        return ImuTruth(roll=0.05 * math.sin(a), pitch=0.08 * math.cos(a), yaw=a,
                        omega_body=(0.01, -0.02, 0.2), accel_body=(0.3, 0.0, 0.0))

    emu = ImuEmulator(clock, truth, seed=1, fault=fault, data_interval_ms=INTERVAL_MS,
                      shift_window_s=(0.0, sim_s))
    n = 0
    t0 = time.process_time()
    for _ in range(round(sim_s / TICK_S)):
        clock.advance(TICK_S)
        n += len(emu.poll())
    return time.process_time() - t0, n


def _baseline(samples: int) -> float:
    block = np.random.default_rng(1).standard_normal(12 * 512)
    at = 0
    out = []
    t0 = time.process_time()
    for _ in range(samples):
        if at + 12 > len(block):
            at = 0
        n = block[at:at + 6]
        at += 12
        out.append(((float(n[0]), float(n[1]), float(n[2])),
                    (float(n[3]), float(n[4]), float(n[5]))))
    return time.process_time() - t0


def _gimbal(sim_s: float) -> float:
    clock = VirtualClock()
    g = PanTiltEmulator(clock, ServoEmulator(clock, min_deg=-90, max_deg=90),
                        ServoEmulator(clock, min_deg=-30, max_deg=45))
    for s in (g.pan, g.tilt):
        s.set_target(0.0)
        s.set_engaged(True)
    t0 = time.process_time()
    for k in range(round(sim_s / TICK_S)):
        clock.advance(TICK_S)
        if k % 50 == 0:  # a levelling correction or a scan step every half second
            g.pan.set_target(60.0 * math.sin(k * 0.01))
            g.tilt.set_target(20.0 * math.cos(k * 0.013))
        g.angles()
        g.pan.take_reached()
    return time.process_time() - t0


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    sim_s = SIM_SECONDS.get(settings.profile, 60.0)
    out: dict[str, Any] = {"simulated_s": sim_s, "data_interval_ms": INTERVAL_MS}
    for fault in ("none", "gyro-drift", "imu-shift"):
        progress(f"autonomy_sensors: IMU emulator, fault {fault}, {sim_s:g} simulated s")
        cpu, n = _imu(sim_s, fault)
        base = _baseline(n)
        out[f"imu_{fault}"] = {
            "samples": n,
            "us_per_sample": compare(round(cpu / n * 1e6, 2), round(base / n * 1e6, 2)),
            "cpu_s_per_simulated_minute": round(cpu / sim_s * 60.0, 4),
        }
    progress("autonomy_sensors: gimbal emulator")
    cpu = _gimbal(sim_s)
    out["gimbal"] = {"us_per_tick": round(cpu / (sim_s / TICK_S) * 1e6, 2),
                     "cpu_s_per_simulated_minute": round(cpu / sim_s * 60.0, 4)}
    return out
