"""`interlocks`: what 20 interlock rules cost a tick and a guarded request (SPEC 11).

Two `ramp run --sim` processes on the MARTE wiring, one with no rules (the baseline) and one
with 20, run alternately `rt_trials` times, the median trial kept:

- **a tick**: each supervisor idles for `tick_duration_s`; the scheduler times every task
  (`bench.child`'s dump), so the figures are the mean cost of a whole tick and of the
  `interlocks` task alone. The difference between the two supervisors is what the rules add.
- **a request**: `rt_requests` sequential `base:lf_wheel.vel=(5)` round trips (client and
  server pinned to one core, as in `round_trip`). Every one of the 20 rules guards that
  function, so each request evaluates all 20: the worst case for a request.

The rules read six different get properties of both modules with one to four comparisons
each, and none of them holds (a rule that holds refuses or clamps, which costs no more), so
the requests run and the comparison is like for like.

- **many rules** (`many_rules`): one trial with 480 such rules, its idle `interlocks` task
  and a guarded request. A tick evaluates only rules whose readings changed, so the idle task
  costs the reads of the six properties; a request still evaluates every rule guarding it.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import yaml

from bench.common import (
    Settings,
    bench_cpu,
    compare,
    connect,
    median_of,
    pinned,
    progress,
    recv_line,
    start_supervisor,
    summary,
    write_config,
)
from bench.tick import tick_cost

RULES = 20
#: Issue 35.6's case: this many rules made the interlocks task cost 10 ms a tick, when every
#: rule was evaluated every tick; one trial of it beside the others, its idle tick reported.
MANY_RULES = 480
REQUEST = b"base:lf_wheel.vel=(5)\n"
STOP = b"base:base.stop=()\n"

_CONDITIONS = (
    "ble:lift.pos < -{i}",
    "ble:lift.pos > 2 and base:battery.volt < {i}",
    "ble:load.kg > 1000 or ble:chain.vel > 100 or ble:lift.stalled == 2",
    "not (base:battery.volt > -{i}) or (base:l_button.press == 2 and ble:lift.pos > 0.5)",
)


def rules(count: int = RULES) -> list[dict[str, Any]]:
    """`count` rules that never hold, every one guarding `base:lf_wheel.vel`."""
    out: list[dict[str, Any]] = []
    for i in range(count):
        rule: dict[str, Any] = {"name": f"bench_{i}",
                                "when": _CONDITIONS[i % len(_CONDITIONS)].format(i=i + 1)}
        if i % 3 == 0:
            rule["limit"] = {"base:*_wheel.vel": 50, "base:base.drive": 50}
        elif i % 3 == 1:
            rule["refuse"] = ["base:lf_wheel.vel", "ble:chain.vel"]
        else:
            rule["stop"] = ["base:*"]
        out.append(rule)
    return out


def config_with(workdir: Path, name: str, count: int) -> Path:
    """MARTE's config served on a free port, with `count` bench rules instead of its own."""
    path = write_config(workdir, name)
    data = yaml.safe_load(path.read_text())
    data["interlocks"] = rules(count) if count else []
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def sequential(port: int, requests: int, warmup: int) -> list[float]:
    """Round trips in µs of `requests` guarded motion requests, one after the other."""
    with connect(port) as sock:
        for _ in range(warmup):
            sock.sendall(REQUEST)
            recv_line(sock)
        out: list[float] = []
        for _ in range(requests):
            t0 = time.perf_counter()
            sock.sendall(REQUEST)
            line = recv_line(sock)
            out.append((time.perf_counter() - t0) * 1e6)
            if line.strip():
                raise RuntimeError(f"the guarded request was answered {line!r}")
        sock.sendall(STOP)
        recv_line(sock)
    return out


def one_trial(name: str, config: Path, workdir: Path, settings: Settings,
              cpu: int) -> dict[str, Any]:
    child, port, dump = start_supervisor(f"interlocks-{name}", config, workdir, cpu=cpu)
    try:
        time.sleep(settings.tick_duration_s)  # idle ticks
        with pinned(cpu):
            rtt = summary(sequential(port, settings.rt_requests, settings.rt_warmup))
        child.terminate()
    finally:
        child.kill()
    data = json.loads(dump.read_text())
    cost = tick_cost(data)
    task = cost["tasks"].get("interlocks", {"mean_us": 0.0, "max_us": 0.0, "runs": 0})
    return {"tick_cost_us": cost["mean_us_per_tick"], "interlocks_task_mean_us": task["mean_us"],
            "interlocks_task_max_us": task["max_us"], "ticks": cost["ticks"],
            "rtt_p50_us": rtt["p50"], "rtt_p99_us": rtt["p99"], "rtt_mean_us": rtt["mean"]}


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    cpu = bench_cpu()
    configs = {"none": config_with(workdir, "interlocks-none", 0),
               "rules": config_with(workdir, "interlocks-20", RULES)}
    trials: dict[str, list[dict[str, Any]]] = {name: [] for name in configs}
    for trial in range(settings.rt_trials):
        for name, config in configs.items():
            progress(f"interlocks: {name}, trial {trial + 1}/{settings.rt_trials}: idle "
                     f"{settings.tick_duration_s:g} s, {settings.rt_requests} requests")
            trials[name].append(one_trial(name, config, workdir, settings, cpu))
    none, some = median_of(trials["none"]), median_of(trials["rules"])
    progress(f"interlocks: {MANY_RULES} rules, one trial")
    many = one_trial("many", config_with(workdir, "interlocks-many", MANY_RULES), workdir,
                     settings, cpu)

    def diff(key: str) -> float | None:
        a, b = some.get(key), none.get(key)
        return None if a is None or b is None else round(a - b, 1)

    return {
        "rules": RULES,
        "request": REQUEST.decode().strip(),
        "guards_per_request": RULES,
        "trials": settings.rt_trials,
        "pinned_cpu": cpu,
        "tick_cost_us": compare(some["tick_cost_us"], none["tick_cost_us"]),
        "tick_cost_added_us": diff("tick_cost_us"),
        "interlocks_task_us": {"mean": some["interlocks_task_mean_us"],
                               "max": some["interlocks_task_max_us"]},
        "request_rtt_p50_us": compare(some["rtt_p50_us"], none["rtt_p50_us"]),
        "request_rtt_added_p50_us": diff("rtt_p50_us"),
        "request_rtt_mean_us": compare(some["rtt_mean_us"], none["rtt_mean_us"]),
        "request_rtt_added_mean_us": diff("rtt_mean_us"),
        "many_rules": {"rules": MANY_RULES,
                       "interlocks_task_us": {"mean": many["interlocks_task_mean_us"],
                                              "max": many["interlocks_task_max_us"]},
                       "tick_cost_us": many["tick_cost_us"],
                       "request_rtt_p50_us": many["rtt_p50_us"]},
        "runs": trials,
    }
