"""`realtime`: the backend's tick during `ramp sim mission --realtime`, the robot and the arena
in their own process (now) beside everything on the autonomy's loop (before, issue 23).

Two runs of the same mission on the wall clock, one after the other: `--single-loop` (the
backend, the emulators and the autonomy on one scheduler in one process, as realtime ran
before) and the default (the robot and the arena in a child process on their own scheduler,
the autonomy in the command's process, `ramp.simulation.arena_process`). Each lasts long
enough to include the initial localization and the 3D scan of the obstacle field, the
autonomy's heaviest work.

The figures are the backend scheduler's own, measured in the process that runs the backend
(`ramp.simulation.arena_process.TickLog` through the scheduler's hooks, over the whole run,
reported in the summary's `backend_tick`): tick lateness p50/p99/max in µs, stalls (the loop
lost more than its 250 ms limit and every motor was stopped) and overruns. Beside them,
`robot:robot.get`'s `tick.late` row read over MCP shortly before the end (the supervisor's
last-minute window), as an operator would see it.
"""

from __future__ import annotations

import json
import re
import socket
import sys
import time
from pathlib import Path
from typing import Any

from bench.common import Child, ChildFailed, Settings, compare, progress

SECONDS = {"full": 75.0, "quick": 40.0, "smoke": 8.0}
SEED = 0
MODES = (("single_loop", ["--single-loop"]), ("apart", []))


def _robot_get_late(host: str, port: int) -> list[int] | None:
    """`robot:tick.late=(p50,p99,max)` in µs, from one `robot:robot.get=()`."""
    try:
        with socket.create_connection((host, port), timeout=5) as sock:
            sock.sendall(b"robot:robot.get=()\n")
            buf = b""
            while not buf.endswith(b"\n"):
                chunk = sock.recv(65536)
                if not chunk:
                    return None
                buf += chunk
    except OSError:
        return None
    m = re.search(r"robot:tick\.late=\((\d+),(\d+),(\d+)\)", buf.decode())
    return [int(g) for g in m.groups()] if m else None


def _one(mode: str, extra: list[str], seconds: float, workdir: Path) -> dict[str, Any]:
    progress(f"realtime: {mode}, a {seconds:g} s mission on the wall clock")
    mission = Child(f"mission-{mode}", [sys.executable, "-m", "ramp.cli", "sim", "mission",
                                        "--realtime", "--port", "0", "--seed", str(SEED),
                                        "--duration", str(seconds), "--json", *extra],
                    workdir)
    try:
        m = mission.expect(r".*MCP on ([\d.]+):(\d+)", 90)
        host, port = m.group(1), int(m.group(2))
        started = time.monotonic()
        lines: list[str] = []
        robot_get: list[int] | None = None
        while True:
            left = seconds - 3.0 - (time.monotonic() - started)
            if robot_get is None and left <= 0:
                robot_get = _robot_get_late(host, port)
            try:
                lines.append(mission.read_line(0.5 if robot_get is None else 60.0))
            except ChildFailed:
                if mission.running() and robot_get is None:
                    continue
                break
            if lines[-1].startswith("{"):
                break
        summary = json.loads(lines[-1])
    finally:
        mission.terminate(20)
    tick = summary.get("backend_tick", {})
    procs = summary.get("processes", {})
    return {
        "late_us": tick.get("late_us"),
        "stalls": tick.get("stalls"),
        "overruns": tick.get("overruns"),
        "ticks": tick.get("samples"),
        "robot_get_late_us": robot_get,
        "processes": 1 if procs.get("autonomy") == procs.get("backend") else 2,
        "outcome": summary.get("outcome"),
        "states_visited": summary.get("states_visited"),
        "wall_s": summary.get("wall_time_s"),
    }


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    seconds = SECONDS.get(settings.profile, SECONDS["quick"])
    out: dict[str, Any] = {"seconds": seconds, "seed": SEED}
    for mode, extra in MODES:
        out[mode] = _one(mode, extra, seconds, workdir)
    before, after = out["single_loop"]["late_us"] or {}, out["apart"]["late_us"] or {}
    out["p99_late_us"] = compare(after.get("p99"), before.get("p99"))
    out["max_late_us"] = compare(after.get("max"), before.get("max"))
    return out
