"""`watchdog_to_wire`: how soon zeros reach the wire when the commanding client is gone.

Partial HIL as in `command_to_wire` (bench/wire.py). Each trial drives all four wheels with
`base:base.drive=(50,0)`, feeds the watchdog with heartbeats for 0.3 s, then either
- goes silent: the figure is the time from its last message to the moment a zero-speed
  packet for every base channel has been read off the pty, minus the configured watchdog
  timeout (what the supervisor adds to the timeout it promises), or
- closes its TCP connection: the time from `close()` to zeros for every channel.
The baseline relay does the same with a select-timeout watchdog and zeros on EOF.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path
from typing import Any

from bench.common import Settings, base_wheels, compare, progress, summary
from bench.wire import (
    TARGETS,
    Target,
    WireTap,
    channel_of,
    open_client,
    read_response,
    start_target,
    watchdog_timeout,
)

DRIVE = b"base:base.drive=(50,0)\n"
FEED_S = 0.3
HEARTBEAT_S = 0.05


def _drive(tap: WireTap, sock: socket.socket) -> float:
    """Drive, feed for FEED_S; returns the time of the last message sent."""
    sock.sendall(DRIVE)
    read_response(tap, sock)
    end = time.monotonic() + FEED_S
    last = time.monotonic()
    while last + HEARTBEAT_S < end:
        tap.idle(HEARTBEAT_S)
        last = time.monotonic()
        sock.sendall(b"\n")
        read_response(tap, sock)
    return last


def _zeros_at(tap: WireTap, mark: int, after: float, wait: float,
              sock: socket.socket | None) -> tuple[float, float] | None:
    """(first, last) time at which each base channel got a zero packet after `after`."""
    channels = {(w.address, w.motor) for w in base_wheels()}  # cached: no YAML parse here
    end = time.monotonic() + wait
    while True:
        first: dict[tuple[int, int], float] = {}
        for t, a, c, d in tap.packets[mark:]:
            ch = channel_of(a, c)
            if ch in channels and d == 0 and t >= after and ch not in first:
                first[ch] = t
        if len(first) == len(channels):
            return min(first.values()), max(first.values())
        now = time.monotonic()
        if now >= end:
            return None
        for s in tap.pump(min(0.05, end - now), [sock] if sock is not None else None):
            if not s.recv(65536):
                sock = None


def trials(target: Target, tap: WireTap, count: int, timeout: float) -> dict[str, Any]:
    silent_ms: list[float] = []
    close_ms: list[float] = []
    spread_ms: list[float] = []
    missed = 0
    with open_client(target) as sock:
        for _ in range(count):
            last = _drive(tap, sock)
            mark = len(tap.packets)
            got = _zeros_at(tap, mark, last, timeout + 2.0, sock)
            if got is None:
                missed += 1
            else:
                silent_ms.append((got[1] - last - timeout) * 1e3)
                spread_ms.append((got[1] - got[0]) * 1e3)
            tap.idle(0.05, [sock])
    for _ in range(count):
        sock = open_client(target)
        try:
            _drive(tap, sock)
            mark = len(tap.packets)
            closed_at = time.monotonic()
        finally:
            sock.close()
        got = _zeros_at(tap, mark, closed_at, 2.0, None)
        if got is None:
            missed += 1
        else:
            close_ms.append((got[1] - closed_at) * 1e3)
            spread_ms.append((got[1] - got[0]) * 1e3)
        tap.idle(0.05)
    return {"silent_ms": silent_ms, "close_ms": close_ms, "spread_ms": spread_ms,
            "missed": missed}


def measure(kind: str, settings: Settings, workdir: Path, timeout: float) -> dict[str, Any]:
    workdir = workdir / kind
    workdir.mkdir(exist_ok=True)
    tap = WireTap(workdir)
    target = start_target(kind, tap, workdir, timeout)
    try:
        progress(f"watchdog_to_wire: {kind}: {settings.wd_trials} silent and "
                 f"{settings.wd_trials} close trials, timeout {timeout:g} s")
        out = trials(target, tap, settings.wd_trials, timeout)
        target.stop()
    finally:
        target.child.kill()
        tap.close()
    return out


def _figure(fig: list[float], base: list[float]) -> dict[str, Any]:
    f, b = summary(fig, 2), summary(base, 2)
    return {"n": f["n"], "p50": compare(f["p50"], b["p50"]), "max": compare(f["max"], b["max"]),
            "mean": compare(f["mean"], b["mean"]), "values": [round(v, 2) for v in fig],
            "baseline_values": [round(v, 2) for v in base]}


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    timeout = watchdog_timeout(settings.wd_timeout_s)
    res = {kind: measure(kind, settings, workdir, timeout) for kind in TARGETS}
    ramp, base = res["supervisor"], res["baseline"]
    return {
        "watchdog_timeout_s": timeout,
        "baseline": {"what": "minimal relay: select-timeout watchdog, zeros on EOF, written "
                             "with pyserial to the same kind of pty"},
        "silent_beyond_timeout_ms": _figure(ramp["silent_ms"], base["silent_ms"]),
        "close_to_zeros_ms": _figure(ramp["close_ms"], base["close_ms"]),
        # First to last channel's zero within one stop: the pacer's doing, 0 for one write.
        "zeros_spread_ms": _figure(ramp["spread_ms"], base["spread_ms"]),
        "missed": {"value": ramp["missed"], "baseline": base["missed"]},
    }
