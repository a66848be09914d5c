"""`round_trip`: `base:base.get=()` over MCP, one at a time and pipelined.

The supervisor is `ramp run --sim` with the MARTE configuration. The baseline, measured in
the same run with the same client code, is a bare `select.select` server that answers each
line with a line of the same size as base.get's response, so the ratio is what RAMP's
parsing, routing, get collection and formatting cost over moving the bytes.

Both servers and this process (the client) are pinned to one core, as a probe running every
process under `taskset -c N` would: the client then waits in `recv` while the server runs,
and no figure includes waking another core (about 50 µs per hop on this VM). Each figure is
measured `rt_trials` times (the sequential one `rt_seq_trials` times), RAMP and baseline
alternating, and the median trial is reported, so a neighbour's burst hits one trial of one
side, not the figure. The sequential p50 is also compared trial by trial
(`p50_ratio_paired`): this VM runs in phases in which the same code's p50 moves by a third,
and a pair of neighbouring trials shares its phase. The supervisor's own tick
lateness during each pipelined phase comes from its lateness samples.
"""

from __future__ import annotations

import json
import select
import socket
import time
from collections import deque
from pathlib import Path
from typing import Any

from bench.common import (
    PYTHON,
    Child,
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
    versus,
    write_config,
)
from bench.tick import window

REQUEST = b"base:base.get=()\n"


def sequential(port: int, requests: int, warmup: int) -> list[float]:
    """Round trips in µs of `requests` requests, each sent after the previous answer."""
    with connect(port) as sock:
        for _ in range(warmup):
            sock.sendall(REQUEST)
            recv_line(sock)
        out: list[float] = []
        for _ in range(requests):
            t0 = time.perf_counter()
            sock.sendall(REQUEST)
            recv_line(sock)
            out.append((time.perf_counter() - t0) * 1e6)
    return out


def _open_clients(port: int, count: int) -> list[socket.socket]:
    """`count` connections, each proven to be served (not refused as busy) by one request."""
    socks: list[socket.socket] = []
    deadline = time.monotonic() + 5
    try:
        while len(socks) < count:
            sock = connect(port)
            sock.sendall(REQUEST)
            line = recv_line(sock)
            if b"error=(busy" in line:  # the previous phase's clients are still closing
                sock.close()
                if time.monotonic() > deadline:
                    raise ConnectionError(f"server stays busy: {line!r}")
                time.sleep(0.05)
                continue
            socks.append(sock)
    except BaseException:
        for s in socks:
            s.close()
        raise
    return socks


def pipelined(port: int, clients: int, in_flight: int, duration: float) -> dict[str, Any]:
    """Each client keeps `in_flight` requests outstanding; answers counted after a warm-up."""
    socks = _open_clients(port, clients)
    sent: dict[int, deque[float]] = {s.fileno(): deque() for s in socks}
    by_fd = {s.fileno(): s for s in socks}
    latency: list[float] = []
    warm = min(0.25, duration / 4)
    start = time.monotonic()
    count_from, end = start + warm, start + warm + duration
    try:
        for sock in socks:
            sent[sock.fileno()].extend([time.perf_counter()] * in_flight)
            sock.sendall(REQUEST * in_flight)
        answered = 0
        while True:
            now = time.monotonic()
            if now >= end:
                break
            readable, _, _ = select.select(socks, [], [], end - now)
            counting = time.monotonic() >= count_from
            for sock in readable:
                data = sock.recv(1 << 18)
                if not data:
                    raise ConnectionError("server closed a pipelining client")
                n = data.count(b"\n")
                t = time.perf_counter()
                q = sent[sock.fileno()]
                for _ in range(n):
                    sent_at = q.popleft()
                    if counting:
                        latency.append((t - sent_at) * 1e6)
                if counting:
                    answered += n
                q.extend([t] * n)
                by_fd[sock.fileno()].sendall(REQUEST * n)
        t_end = time.monotonic()
    finally:
        for sock in socks:
            sock.close()
    return {"req_per_s": round(answered / (t_end - count_from)), "latency_us": summary(latency),
            "window": (count_from, t_end)}


def measure(ports: dict[str, int], settings: Settings) -> dict[str, dict[str, Any]]:
    """Every figure for each server, trials alternating between them; medians per figure."""
    seq: dict[str, list[dict[str, Any]]] = {name: [] for name in ports}
    piped: dict[str, dict[int, list[dict[str, Any]]]] = {
        name: {n: [] for n in settings.tp_clients} for name in ports}
    for trial in range(settings.rt_seq_trials):
        for name, port in (ports.items() if trial % 2 == 0 else reversed(ports.items())):
            progress(f"round_trip: {name}, trial {trial + 1}/{settings.rt_seq_trials}: "
                     f"{settings.rt_requests} sequential requests")
            seq[name].append(summary(sequential(port, settings.rt_requests,
                                                settings.rt_warmup)))
    for n in settings.tp_clients:
        for trial in range(settings.rt_trials):
            for name, port in ports.items():
                progress(f"round_trip: {name}, trial {trial + 1}/{settings.rt_trials}: "
                         f"{n} clients x {settings.tp_in_flight} in flight, "
                         f"{settings.tp_duration_s:g} s")
                piped[name][n].append(pipelined(port, n, settings.tp_in_flight,
                                                settings.tp_duration_s))
                time.sleep(0.1)  # let the server see the previous clients' close
    out: dict[str, dict[str, Any]] = {}
    for name in ports:
        figs: dict[str, Any] = {"sequential_rtt_us": median_of(seq[name]),
                                "sequential_p50_us": [r["p50"] for r in seq[name]]}
        for n, runs in piped[name].items():
            by_rate = sorted(runs, key=lambda r: r["req_per_s"])
            middle = by_rate[len(by_rate) // 2]
            figs[f"clients_{n}"] = {
                "req_per_s": middle["req_per_s"],
                "latency_us": median_of([r["latency_us"] for r in runs]),
                "windows": [r["window"] for r in runs],
                "trials_req_per_s": [r["req_per_s"] for r in runs],
            }
        out[name] = figs
    return out


def paired_ratio(values: list[float], baselines: list[float]) -> dict[str, Any]:
    """The p50 ratio of each trial against the baseline's trial beside it, and their median:
    a phase of the machine (both slower for a while) cancels out in each pair."""
    ratios = sorted(round(v / b, 3) for v, b in zip(values, baselines, strict=True) if b)
    return {"median": ratios[len(ratios) // 2] if ratios else None, "trials": ratios}


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    cpu = bench_cpu()
    config = write_config(workdir, "round_trip")
    child, port, dump = start_supervisor("round_trip", config, workdir, cpu=cpu)
    bare: Child | None = None
    try:
        with connect(port) as sock:
            sock.sendall(REQUEST)
            response_bytes = len(recv_line(sock))
        bare = Child("bare-server", [PYTHON, "-m", "bench.child", "bare-server", "--size",
                                     str(response_bytes)], workdir, cpu=cpu)
        m = bare.expect(r"ready on [\d.]+:(\d+)", 30)
        with pinned(cpu):
            figs = measure({"supervisor": port, "baseline": int(m.group(1))}, settings)
        child.terminate()
        bare.terminate()
    finally:
        child.kill()
        if bare is not None:
            bare.kill()
    samples = json.loads(dump.read_text())["samples"]
    ramp, base = figs["supervisor"], figs["baseline"]

    out: dict[str, Any] = {
        "request": REQUEST.decode().strip(),
        "response_bytes": response_bytes,
        "pinned_cpu": cpu,
        "trials": settings.rt_trials,
        "baseline": {"what": "bare select.select line server answering each line with "
                             f"{response_bytes} bytes",
                     "sequential_rtt_us": base["sequential_rtt_us"]},
        "sequential": {"requests": settings.rt_requests, "trials": settings.rt_seq_trials,
                       "rtt_us": versus(ramp["sequential_rtt_us"], base["sequential_rtt_us"]),
                       "p50_ratio_paired": paired_ratio(ramp["sequential_p50_us"],
                                                        base["sequential_p50_us"])},
        "pipelined": {"in_flight_per_client": settings.tp_in_flight,
                      "duration_s": settings.tp_duration_s},
    }
    for n in settings.tp_clients:
        fig, ref = ramp[f"clients_{n}"], base[f"clients_{n}"]
        late: list[float] = []
        overruns = 0
        for window_ in fig["windows"]:
            got, over = window(samples, *window_)
            late += got
            overruns += over
        out["pipelined"][f"clients_{n}"] = {
            "req_per_s": compare(fig["req_per_s"], ref["req_per_s"]),
            "trials_req_per_s": {"value": fig["trials_req_per_s"],
                                 "baseline": ref["trials_req_per_s"]},
            "latency_us": {k: compare(fig["latency_us"][k], ref["latency_us"][k])
                           for k in ("p50", "p99", "max")},
            # How the supervisor's own ticks fared while it was saturated.
            "tick_late_us": summary(late),
            "tick_overruns": overruns,
        }
    return out
