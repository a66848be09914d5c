"""`tick`: how late the supervisor's ticks start, what one costs, and the CPU it takes.

The MARTE configuration runs as a real `ramp run --sim` process on the wall clock (through
`bench.child supervisor`, whose observer keeps every lateness sample and each task's cost;
`robot.get` only has p50/p99/max over a window), idle and while MCP clients poll it; and
idle as `ramp run` on real drivers: the Sabertooth driver on ptys served by emulator
processes, the Phidget driver on a stand-in of the vendor library
(the tests' fake of it, `tests/fake_phidget22.serve`, whose own thread delivers samples as
libphidget22's does).
Lateness is wake time minus the absolute deadline, as in
shared/reference/platform-limits.md. The baseline is a bare absolute-deadline loop waiting in
`select.select` with a microsecond timeout, doing nothing, at the same rate for the same time
in its own process, run *at the same time* as each supervisor run and cut to the same
window: on a shared machine the neighbours' load then hits both alike (each uses a few % of
one core, so they rarely meet). It is the floor this machine allows any Python loop.

The supervisor here ticks every base period (`scheduler.idle_rate_hz` set to the base rate):
an idle `ramp run` otherwise ticks at 20 Hz, and these are the figures of its 100 Hz loop,
what it runs at whenever something moves. The `startup` section measures the idle CPU both
ways.
"""

from __future__ import annotations

import json
import select
import time
from collections import deque
from pathlib import Path
from typing import Any

from bench.common import (
    PYTHON,
    Child,
    Settings,
    compare,
    connect,
    load_marte,
    progress,
    robot_health,
    start_supervisor,
    summary,
    versus,
    write_config,
)

POLL_MESSAGE = b"base:base.get=()ble:ble.get=()\n"


def window(samples: list[list[float]], t0: float, t1: float) -> tuple[list[float], int]:
    """Lateness (µs) of the ticks inside [t0, t1] and the overruns counted meanwhile."""
    inside = [s for s in samples if t0 <= s[0] <= t1]
    if not inside:
        return [], 0
    return [s[1] for s in inside], int(inside[-1][2] - inside[0][2])


class BaselineLoop:
    """The bare select loop in its own process, running beside the supervisor."""

    def __init__(self, rate: float, workdir: Path) -> None:
        self.rate = rate
        self.child = Child("select-loop", [PYTHON, "-m", "bench.child", "select-loop",
                                           "--rate", str(rate)], workdir, stdin=True)
        self.child.expect("start", 30)

    def finish(self, t0: float, t1: float, cpu_s: float) -> dict[str, Any]:
        """Stop it; its lateness inside [t0, t1] and its CPU % over that window."""
        try:
            self.child.write_line("stop")
            result = json.loads(self.child.read_line(30))
            self.child.proc.wait(timeout=10)
        finally:
            self.child.kill()
        period_us = 1e6 / self.rate
        late = [s[1] for s in result["samples"] if t0 <= s[0] <= t1]
        return {
            "late_us": summary(late),
            "overruns": sum(1 for v in late if v >= period_us),
            "cpu_pct": round(100 * cpu_s / (t1 - t0), 2),
        }


def poll(port: int, clients: int, hz: float, duration: float,
         message: bytes = POLL_MESSAGE) -> list[float]:
    """`clients` connections each sending `message` (POLL_MESSAGE) at `hz` on absolute
    deadlines, staggered evenly; returns every response's round trip in µs."""
    socks = [connect(port) for _ in range(clients)]
    period = 1.0 / hz
    rtt_us: list[float] = []
    sent: list[deque[float]] = [deque() for _ in socks]
    index = {s.fileno(): i for i, s in enumerate(socks)}
    start = time.monotonic()
    end = start + duration
    due = [start + i * period / clients for i in range(clients)]
    try:
        while True:
            now = time.monotonic()
            if now >= end:
                break
            for i, sock in enumerate(socks):
                if now >= due[i]:
                    sent[i].append(time.monotonic())
                    sock.sendall(message)
                    while due[i] <= now:
                        due[i] += period
            timeout = max(0.0, min(min(due), end) - time.monotonic())
            readable, _, _ = select.select(socks, [], [], timeout)
            t = time.monotonic()
            for sock in readable:
                data = sock.recv(65536)
                if not data:
                    raise ConnectionError("the supervisor closed a polling client")
                q = sent[index[sock.fileno()]]
                for _ in range(data.count(b"\n")):
                    rtt_us.append((t - q.popleft()) * 1e6)
    finally:
        for sock in socks:
            sock.close()
    return rtt_us


def tick_cost(data: dict[str, Any]) -> dict[str, Any]:
    """What the tasks of one tick cost (the scheduler times each task): mean per tick, and per
    task its mean and max per run."""
    ticks = max(1, int(data.get("ticks", 0)))
    tasks = data.get("tasks", {})
    per_task = {name: {"mean_us": round(1e6 * t["total_s"] / max(1, t["runs"]), 1),
                       "max_us": round(1e6 * t["max_s"], 1), "runs": t["runs"]}
                for name, t in tasks.items()}
    total = sum(t["total_s"] for t in tasks.values())
    return {"mean_us_per_tick": round(1e6 * total / ticks, 1), "ticks": ticks,
            "tasks": per_task}


def supervised(config: Path, workdir: Path, duration: float, rate: float,
               settings: Settings | None, real: bool = False,
               extra: tuple[str, ...] = ()) -> dict[str, Any]:
    """One run of the supervisor (idle when `settings` is None, else under the poll load),
    with the baseline loop measured over the same window."""
    base = BaselineLoop(rate, workdir)
    try:
        child, port, dump = start_supervisor("tick", config, workdir, real=real, extra=extra)
        try:
            t0 = time.monotonic()
            cpu0, bcpu0 = child.cpu_seconds(), base.child.cpu_seconds()
            rtt: list[float] = []
            if settings is None:
                time.sleep(duration)
            else:
                rtt = poll(port, settings.poll_clients, settings.poll_hz, duration)
            t1 = time.monotonic()
            cpu1, bcpu1 = child.cpu_seconds(), base.child.cpu_seconds()
            own_view = robot_health(port)
            child.terminate()
        finally:
            child.kill()
        ref = base.finish(t0, t1, bcpu1 - bcpu0)
    finally:
        base.child.kill()
    data = json.loads(dump.read_text())
    late, overruns = window(data["samples"], t0, t1)
    cpu = round(100 * (cpu1 - cpu0) / (t1 - t0), 2)
    cost = tick_cost(data)
    busy = summary(s[1] for s in data.get("busy", []) if t0 <= s[0] <= t1)
    per_iteration = round(ref["cpu_pct"] / 100 / rate * 1e6, 1)
    out: dict[str, Any] = {
        "late_us": versus(summary(late), ref["late_us"]),
        "overruns": compare(overruns, ref["overruns"]),
        "cpu_pct": compare(cpu, ref["cpu_pct"]),
        # What a tick takes (its tasks and their bookkeeping, timed by the loop) beside what
        # one iteration of the bare loop costs the machine (its CPU over its iterations).
        "tick_busy_us": {k: compare(busy[k], per_iteration) for k in ("p50", "p99", "mean")},
        "tick_cost_us": compare(cost["mean_us_per_tick"], per_iteration),
        "tasks": cost["tasks"],
        "ticks": len(late),
        "expected_ticks": int(round((t1 - t0) * rate)),
        "baseline_late_us": ref["late_us"],
        # p50/p99 over the scheduler's own window (which may include start-up), max since
        # start: a cross-check of the hook, as an operator would read it.
        "robot_get": own_view,
    }
    if settings is not None:
        out["load"] = {
            "clients": settings.poll_clients, "hz_each": settings.poll_hz,
            "message": POLL_MESSAGE.decode().strip(),
            "rtt_us": summary(rtt),
        }
    return out


def real_drivers(workdir: Path, duration: float, rate: float) -> dict[str, Any]:
    """Idle on real drivers: each Sabertooth bus on the pty of an emulator process, the
    Phidget boards through the vendor-library stand-in."""
    emulators: list[Child] = []
    try:
        ports = {}
        for bus, addresses in (("base_motors", "128,129"), ("ble_motors", "130,131")):
            where = workdir / bus
            where.mkdir(exist_ok=True)
            emu = Child(f"sabertooth-{bus}", [PYTHON, "-m", "firmware_like.sabertooth",
                                              "--addresses", addresses, "--paced", "--quiet",
                                              "--dir", str(where)], workdir)
            emulators.append(emu)
            ports[bus] = emu.expect(r"sabertooth emulator on (\S+)", 30).group(1)
        config = write_config(workdir, "tick-real", ports=ports, every_tick=True)
        return supervised(config, workdir, duration, rate, None, real=True,
                          extra=("--fake-phidget22",))
    finally:
        for emu in emulators:
            emu.kill()


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    rate = float(load_marte()["scheduler"]["rate_hz"])
    duration = settings.tick_duration_s
    config = write_config(workdir, "tick", every_tick=True)
    progress(f"tick: supervisor idle, {rate:g} Hz for {duration:g} s, baseline loop beside it")
    idle = supervised(config, workdir, duration, rate, None)
    progress(f"tick: supervisor with {settings.poll_clients} clients polling at "
             f"{settings.poll_hz:g} Hz, {duration:g} s, baseline loop beside it")
    loaded = supervised(config, workdir, duration, rate, settings)
    progress(f"tick: supervisor idle on real drivers (Sabertooth emulator processes, the "
             f"Phidget library stand-in), {duration:g} s, baseline loop beside it")
    real = real_drivers(workdir, duration, rate)
    return {
        "rate_hz": rate, "duration_s": duration,
        "baseline": "bare absolute-deadline loop waiting in select.select (µs timeout), "
                    "doing nothing, in its own process, running at the same time as the "
                    "supervisor so both see the same neighbours",
        "idle": idle, "loaded": loaded, "real_drivers_idle": real,
    }
