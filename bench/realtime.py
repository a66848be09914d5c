"""`realtime`: the backend's tick during `ramp sim mission --realtime`, as `make mission` runs it.

The backend runs in a process of its own exactly as `ramp run` runs it (the stall guard's
thread, `gc.freeze()`, SCHED_FIFO where permitted: `ramp.runtime.service.serve`), on the
wires of the simulated hardware, which runs in the simulator's process with the world's
physics and the LIDAR's ray casting; the autonomy runs in the command's process
(`ramp.simulation.arena_process`, `ramp.simulation.backend_process`). Two runs of the same
mission on the wall clock, one after the other: `bare` (nobody attached), `attached` (the
live view served, `--foxglove-port 0`, the console, `ramp-teleop`, connected to the backend
and to the live view, and a headless Chromium page open on the console, as an operator
watches `make mission`), and `attached_default_priority`, the same with the backend at the
default priority (where SCHED_FIFO is permitted, what it buys; where it is not, the backend
runs so anyway; `--quick` leaves this third run out). Each lasts long enough to include the
initial localization and the 3D scan of the obstacle field, the autonomy's heaviest work (not
in `--quick`'s 4 s missions, a look that the machinery runs).

The figures are the backend scheduler's own, measured in the backend's process
(`ramp.simulation.arena_process.TickLog` through the scheduler's hooks, over the whole run,
reported in the summary's `backend_tick`): tick lateness p50/p99/max in µs, stalls (the loop
lost more than its 250 ms limit and every motor was stopped) and overruns; beside them the
simulator's own loop (`simulator_tick`), how the backend ran (`backend_service`), and
`robot:robot.get`'s `tick.late` row as an operator sees it over MCP (the supervisor's window
of the last minute, read every 5 s; the last answer is kept). Baseline, in the same run: the
tick benchmark's bare absolute-deadline `select` loop (`bench.child select-loop`, 100 Hz,
doing nothing, at the default priority) in a process of its own beside each mission, cut to
the same window: what the machine's scheduler gives any loop at that moment.
"""

from __future__ import annotations

import json
import re
import socket
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.common import Child, ChildFailed, Settings, compare, progress
from bench.tick import BaselineLoop

#: Quick: three short missions keep `--quick` under two minutes (each costs about 3 s to start).
SECONDS = {"full": 90.0, "quick": 4.0, "smoke": 4.0}
ROBOT_GET_EVERY_S = 5.0
SEED = 0
#: (name, attached, the mission's extra arguments): the last runs the backend at the default
#: priority, to say what the service's SCHED_FIFO buys where it is permitted.
MODES: tuple[tuple[str, bool, list[str]], ...] = (
    ("bare", False, []), ("attached", True, []),
    ("attached_default_priority", True, ["--backend-default-priority"]))
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync"]


class Console:
    """`ramp-teleop` on the backend and the live view, and a headless Chromium page open on
    it (Playwright driving Debian's chromium), until `close`."""

    def __init__(self, backend: str, view: str, workdir: Path) -> None:
        self.teleop = Child("realtime-teleop", [
            sys.executable, "-m", "ramp.teleop", "--backend", backend, "--autonomy", view,
            "--http-port", "0", "--name", "bench"], workdir)
        self._pw: Any = None
        self._context: Any = None
        try:
            self.url = self.teleop.expect(r".*ramp-teleop: open (http://[\d.]+:\d+/)", 30).group(1)
            from playwright.sync_api import sync_playwright

            self._profile = tempfile.TemporaryDirectory(prefix="ramp-bench-chromium-")
            self._pw = sync_playwright().start()
            self._context = self._pw.chromium.launch_persistent_context(
                self._profile.name, executable_path=CHROMIUM, headless=True,
                args=CHROMIUM_FLAGS, viewport={"width": 1400, "height": 1000})
            self.page = self._context.new_page()
            self.page.goto(self.url)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        if self._context is not None:
            self._context.close()
            self._context = None
        if self._pw is not None:
            self._pw.stop()
            self._pw = None
            self._profile.cleanup()
        self.teleop.terminate(10)


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


def _one(mode: str, attached: bool, more: list[str], seconds: float,
         workdir: Path) -> dict[str, Any]:
    progress(f"realtime: {mode}, a {seconds:g} s mission on the wall clock")
    base = BaselineLoop(100.0, workdir)
    extra = (["--foxglove-port", "0"] if attached else []) + more
    mission = Child(f"mission-{mode}", [sys.executable, "-m", "ramp.cli", "sim", "mission",
                                        "--realtime", "--port", "0", "--seed", str(SEED),
                                        "--duration", str(seconds), "--json", *extra],
                    workdir)
    t0 = t1 = time.monotonic()
    console: Console | None = None
    try:
        # The live view's address is printed before the MCP line.
        view = mission.expect(r".*foxglove live on ws://([\d.]+:\d+)", 90).group(1) \
            if attached else ""
        m = mission.expect(r".*MCP on ([\d.]+):(\d+)", 90)
        host, port = m.group(1), int(m.group(2))
        if attached:
            console = Console(f"{host}:{port}", view, workdir)
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
        if console is not None:
            console.close()
        mission.terminate(20)
        baseline = base.finish(t0, max(t1, t0 + 1e-3), 0.0)  # (t1 == t0 if it failed)
    tick = summary.get("backend_tick", {})
    sim_tick = summary.get("simulator_tick", {})
    procs = summary.get("processes", {})
    return {
        "late_us": tick.get("late_us"),
        "stalls": tick.get("stalls"),
        "overruns": tick.get("overruns"),
        "ticks": tick.get("samples"),
        "attached": ["console", "live view", "chromium"] if attached else [],
        "backend_service": summary.get("backend_service"),
        "simulator_late_us": sim_tick.get("late_us"),
        "robot_get_late_us": robot_get,
        "baseline_late_us": {k: baseline["late_us"].get(k) for k in ("p50", "p99", "max")},
        "processes": len(set(procs.values())),
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
    for mode, attached, more in MODES:
        if settings.profile == "quick" and mode == "attached_default_priority":
            continue  # under two minutes for the whole quick run
        out[mode] = _one(mode, attached, more, seconds, workdir)
    # The attached run's tick beside the bare select loop's in the same window.
    run_, base = out["attached"]["late_us"] or {}, out["attached"]["baseline_late_us"]
    out["p99_late_us"] = compare(run_.get("p99"), base.get("p99"))
    out["max_late_us"] = compare(run_.get("max"), base.get("max"))
    return out
