"""`startup`: process start to `ramp: ready`, resident memory, idle CPU, and SIGTERM to exit.

The real command line, `python -m ramp.cli run --sim` with the repository's ramp.yaml (no
bench hooks), started several times; the median is reported. The baseline is a bare
interpreter printing the same line (`python -c 'print(...)'`), interleaved run by run so a
busy moment hits both. The last process of each kind stays up for the memory reading, and
meanwhile the idle CPU of that `ramp run --sim` (utime + stime of every thread over the
window, as a probe reading /proc would) is measured beside the tick benchmark's bare
100 Hz select loop running over the same window (`bench.tick.BaselineLoop`), and beside the
same robot with idle ticks off (`scheduler.idle_rate_hz` at the base rate: every base period
ticks, as whenever something moves).
"""

from __future__ import annotations

import os
import select
import statistics
import time
import tty
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench.common import (
    MARTE_YAML,
    PYTHON,
    Child,
    Settings,
    compare,
    load_marte,
    progress,
    write_config,
)
from bench.tick import BaselineLoop

READY = r"ramp: ready on "
RAMP_ARGV = [PYTHON, "-m", "ramp.cli", "run", "--sim", "--config", str(MARTE_YAML),
             "--host", "127.0.0.1", "--port", "0", "--log-level", "warning"]
BARE_ARGV = [PYTHON, "-c",
             "import time; print('ramp: ready on 127.0.0.1:0', flush=True); time.sleep(3600)"]


def _per_call_us(fn: Callable[[], object], samples: int, cold: bool) -> float:
    """Median µs of one `fn()`: back to back (hot), or each after a 10 ms sleep (cold), as
    every idle tick's work runs."""
    out = []
    for _ in range(samples):
        if cold:
            select.select([], [], [], 0.01)
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1e6)
    return round(statistics.median(out), 2)


def cold_costs(samples: int) -> dict[str, dict[str, float]]:
    """What the smallest pieces of a tick cost on this machine hot and after 10 ms asleep:
    the idle CPU of a 100 Hz loop is paid at the cold price."""
    fds = []
    for _ in range(2):
        master, slave = os.openpty()
        tty.setraw(slave)
        fds += [master, slave]
    poller = select.poll()
    for fd in fds[::2]:
        poller.register(fd, select.POLLIN)
    pieces: dict[str, Callable[[], object]] = {
        "noop_call": lambda: None, "clock_read": time.monotonic,
        "poll_of_2_ptys": lambda: poller.poll(0)}
    try:
        return {name: {"hot_us": _per_call_us(fn, samples, False),
                       "cold_us": _per_call_us(fn, samples, True)}
                for name, fn in pieces.items()}
    finally:
        for fd in fds:
            os.close(fd)


def _start(name: str, argv: list[str], workdir: Path) -> tuple[Child, float]:
    t0 = time.monotonic()
    child = Child(name, argv, workdir)
    try:
        child.expect(READY, 30)
    except BaseException:
        child.kill()
        raise
    return child, (time.monotonic() - t0) * 1e3


def _stop_ms(child: Child) -> float:
    t0 = time.monotonic()
    child.terminate()
    return (time.monotonic() - t0) * 1e3


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    ramp_ms: list[float] = []
    bare_ms: list[float] = []
    ramp_stop: list[float] = []
    bare_stop: list[float] = []
    progress(f"startup: {settings.startup_runs} starts of ramp run --sim and of a bare "
             "interpreter")
    ramp = bare = every = None
    try:
        for i in range(settings.startup_runs):
            last = i == settings.startup_runs - 1
            ramp, ms = _start("ramp", RAMP_ARGV, workdir)
            ramp_ms.append(ms)
            bare, ms = _start("bare", BARE_ARGV, workdir)
            bare_ms.append(ms)
            if not last:
                ramp_stop.append(_stop_ms(ramp))
                bare_stop.append(_stop_ms(bare))
        assert ramp is not None and bare is not None
        rss_ready = (ramp.status_kb("VmRSS"), bare.status_kb("VmRSS"))
        progress(f"startup: resident memory and idle CPU over {settings.rss_after_s:g} s, "
                 "a bare select loop beside it")
        rate = float(load_marte()["scheduler"]["rate_hz"])
        # The same robot with idle ticks off (every base period ticks, as whenever something
        # moves), over the same window: what the idle ticks save.
        every_yaml = write_config(workdir, "startup-every-tick", every_tick=True)
        every, _ = _start("ramp-every-tick", [str(every_yaml) if a == str(MARTE_YAML) else a
                                              for a in RAMP_ARGV], workdir)
        loop = BaselineLoop(rate, workdir)
        try:
            t0 = time.monotonic()
            cpu0, loop0 = ramp.cpu_seconds(), loop.child.cpu_seconds()
            every0 = every.cpu_seconds()
            time.sleep(settings.rss_after_s)
            t1 = time.monotonic()
            cpu1, loop1 = ramp.cpu_seconds(), loop.child.cpu_seconds()
            every1 = every.cpu_seconds()
            idle_cpu = round(100 * (cpu1 - cpu0) / (t1 - t0), 2)
            every_cpu = round(100 * (every1 - every0) / (t1 - t0), 2)
            loop_cpu = loop.finish(t0, t1, loop1 - loop0)["cpu_pct"]
        finally:
            loop.child.kill()
            every.kill()  # before the memory readings: its CPU is no longer wanted
        rss_later = (ramp.status_kb("VmRSS"), bare.status_kb("VmRSS"))
        hwm = (ramp.status_kb("VmHWM"), bare.status_kb("VmHWM"))
        threads = ramp.status_kb("Threads")
        ramp_stop.append(_stop_ms(ramp))
        bare_stop.append(_stop_ms(bare))
    finally:
        for child in (ramp, bare, every):
            if child is not None:
                child.kill()

    def mb(kb: int | None) -> float | None:
        return None if kb is None else round(kb / 1024, 1)

    return {
        "command": " ".join(["python", *RAMP_ARGV[1:]]).replace(str(MARTE_YAML), "ramp.yaml"),
        "baseline": {"what": "bare interpreter: python -c \"print('ramp: ready ...')\""},
        "runs": settings.startup_runs,
        "start_to_ready_ms": {
            "median": compare(round(statistics.median(ramp_ms), 1),
                              round(statistics.median(bare_ms), 1)),
            "min": compare(round(min(ramp_ms), 1), round(min(bare_ms), 1)),
            "max": compare(round(max(ramp_ms), 1), round(max(bare_ms), 1)),
            "values": [round(v, 1) for v in ramp_ms],
            "baseline_values": [round(v, 1) for v in bare_ms],
        },
        "rss_mb_at_ready": compare(mb(rss_ready[0]), mb(rss_ready[1])),
        "rss_mb_after": {"seconds": settings.rss_after_s,
                         **compare(mb(rss_later[0]), mb(rss_later[1]))},
        "peak_rss_mb": compare(mb(hwm[0]), mb(hwm[1])),
        # Issue 35's probe: `ramp run --sim` idle, beside a bare 100 Hz select loop doing
        # nothing over the same window (goal: at most 2 % of a core and 35 MB resident).
        # It ticks at `scheduler.idle_rate_hz` (20 Hz) while nothing moves; the same robot
        # ticking every base period over the same window beside it.
        "idle_cpu_pct": {"seconds": settings.rss_after_s, "rate_hz": rate,
                         "baseline_is": "bare select loop at the same rate",
                         **compare(idle_cpu, loop_cpu)},
        "idle_cpu_pct_every_tick": {"seconds": settings.rss_after_s, "rate_hz": rate,
                                    "baseline_is": "bare select loop at the same rate",
                                    **compare(every_cpu, loop_cpu)},
        # Why the idle figure is what it is: each tick's work runs on a cold cache.
        "cold_costs": cold_costs(100 if settings.profile == "full" else 30),
        "threads": threads,  # the stall guard is the one extra thread
        "sigterm_to_exit_ms": {
            "median": compare(round(statistics.median(ramp_stop), 1),
                              round(statistics.median(bare_stop), 1)),
            "max": compare(round(max(ramp_stop), 1), round(max(bare_stop), 1)),
        },
    }
