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
`robot:robot.get`'s `tick.late` row as an operator sees it over MCP (the supervisor's window
of the last minute, read every 5 s; the last answer is kept). Baseline, in the same run: the
tick benchmark's bare absolute-deadline `select` loop (`bench.child select-loop`, 100 Hz,
doing nothing) in a process of its own beside each mission, cut to the same window: what the
machine's scheduler gives any loop at that moment (on a shared 2-core machine, most of the
p99).
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
from bench.tick import BaselineLoop

SECONDS = {"full": 90.0, "quick": 8.0, "smoke": 4.0}
ROBOT_GET_EVERY_S = 5.0
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
    base = BaselineLoop(100.0, workdir)
    mission = Child(f"mission-{mode}", [sys.executable, "-m", "ramp.cli", "sim", "mission",
                                        "--realtime", "--port", "0", "--seed", str(SEED),
                                        "--duration", str(seconds), "--json", *extra],
                    workdir)
    t0 = t1 = time.monotonic()
    try:
        m = mission.expect(r".*MCP on ([\d.]+):(\d+)", 90)
        host, port = m.group(1), int(m.group(2))
        t0 = time.monotonic()
        deadline = t0 + seconds + 60.0
        lines: list[str] = []
        robot_get: list[int] | None = None
        asked = t0
        while time.monotonic() < deadline:
            if time.monotonic() - asked >= ROBOT_GET_EVERY_S:
                asked = time.monotonic()
                robot_get = _robot_get_late(host, port) or robot_get
            try:
                lines.append(mission.read_line(0.5))
            except ChildFailed:
                if mission.running():
                    continue
                break
            if lines[-1].startswith("{"):
                break
        t1 = time.monotonic()
        summary = summary_of(mode, lines)
    finally:
        mission.terminate(20)
        baseline = base.finish(t0, t1, 0.0)
    tick = summary.get("backend_tick", {})
    procs = summary.get("processes", {})
    return {
        "late_us": tick.get("late_us"),
        "stalls": tick.get("stalls"),
        "overruns": tick.get("overruns"),
        "ticks": tick.get("samples"),
        "robot_get_late_us": robot_get,
        "baseline_late_us": {k: baseline["late_us"].get(k) for k in ("p50", "p99", "max")},
        "processes": 1 if procs.get("autonomy") == procs.get("backend") else 2,
        "outcome": summary.get("outcome"),
        "states_visited": summary.get("states_visited"),
        "wall_s": summary.get("wall_time_s"),
    }


def summary_of(mode: str, lines: list[str]) -> dict[str, Any]:
    """The mission's JSON summary, its last line; ValueError naming `mode` and quoting what
    came instead when there is none."""
    last = lines[-1].strip() if lines else ""
    if not last.startswith("{"):
        raise ValueError(f"realtime: the {mode} mission printed no JSON summary; its last "
                         f"line: {last[:200]!r}" if lines else
                         f"realtime: the {mode} mission printed nothing")
    try:
        summary = json.loads(last)
    except ValueError as exc:
        raise ValueError(f"realtime: the {mode} mission's summary is not JSON ({exc}): "
                         f"{last[:200]!r}") from exc
    if not isinstance(summary, dict):
        raise ValueError(f"realtime: the {mode} mission's summary is not an object: "
                         f"{last[:200]!r}")
    return summary


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    seconds = SECONDS.get(settings.profile, SECONDS["quick"])
    out: dict[str, Any] = {"seconds": seconds, "seed": SEED}
    for mode, extra in MODES:
        out[mode] = _one(mode, extra, seconds, workdir)
    before, after = out["single_loop"]["late_us"] or {}, out["apart"]["late_us"] or {}
    out["p99_late_us"] = compare(after.get("p99"), before.get("p99"))
    out["max_late_us"] = compare(after.get("max"), before.get("max"))
    return out
