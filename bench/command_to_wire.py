"""`command_to_wire`: from a client's `base:WHEEL.vel=(N)` send to its packet on the pty.

Partial HIL (see bench/wire.py): the supervisor's real Sabertooth driver at 9600 baud writes
to a pty read here. Three phases per target:
- single commands, one at a time with 5-15 ms between them (so they land all over the tick);
- a flood of 1000 commands/s on `lf_wheel` alone, and one spread over the four wheels.
  Under a flood the driver's budget (baud/10 bytes/s, newest value wins) lets only some
  values out: for each packet we find the command whose value it carries (the newest one
  not yet seen on the wire), and report its age on arrival, how far it lags the newest
  command sent by then, and which share of commands ever reached the wire.
The baseline relay writes every command at once and ignores the wire budget: it is the floor
of "TCP line in, pyserial write, pty read", not a competitor at 9600 baud.
The driver's own counters (including `max_pending`) come from the supervisor's dump.
"""

from __future__ import annotations

import random
import socket
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bench.common import Settings, Wheel, base_wheels, compare, progress, summary, versus
from bench.wire import (
    TARGETS,
    Key,
    WireTap,
    channel_of,
    expected_key,
    open_client,
    read_response,
    start_target,
    watchdog_timeout,
)

BAUD = 9600
PACKET_BITS = 40  # 4 bytes, 8N1


def value_sequence(k: int, offset: int = 0) -> int:
    """The k-th velocity for a channel: -100..100, never equal to the previous one, and a
    value repeats only after 201 commands, so a packet's value names its command."""
    return (k * 37 + offset) % 201 - 100


def singles(tap: WireTap, sock: socket.socket, wheel: Wheel, count: int
            ) -> dict[str, Any]:
    rng = random.Random(5)
    wire_us: list[float] = []
    response_us: list[float] = []
    missing = 0
    for k in range(1, count + 1):
        vel = value_sequence(k)
        want = expected_key(wheel, vel)
        mark = len(tap.packets)
        t0 = time.monotonic()
        sock.sendall(f"base:{wheel.name}.vel=({vel})\n".encode())
        read_response(tap, sock)
        response_us.append((time.monotonic() - t0) * 1e6)
        end = t0 + 1.0
        seen = None
        while seen is None and time.monotonic() < end:
            for t, a, c, d in tap.packets[mark:]:
                if (a, c, d) == want:
                    seen = t
                    break
            else:
                mark = len(tap.packets)
                tap.pump(end - time.monotonic())
        if seen is None:
            missing += 1
        else:
            wire_us.append((seen - t0) * 1e6)
        tap.idle(rng.uniform(0.005, 0.015), [sock])
    return {"wire_us": wire_us, "response_us": response_us, "missing": missing}


def flood(tap: WireTap, sock: socket.socket, wheels: Sequence[Wheel], hz: float,
          duration: float) -> dict[str, Any]:
    """Send `hz` commands/s round-robin over `wheels`, then match packets to commands."""
    sent: dict[tuple[int, int], list[tuple[float, Key]]] = {
        (w.address, w.motor): [] for w in wheels}
    counters = dict.fromkeys(sent, 0)
    offsets = {ch: 50 * i for i, ch in enumerate(sent)}
    mark = len(tap.packets)
    period = 1.0 / hz
    start = time.monotonic()
    end = start + duration
    due = start
    k = 0
    responses = b""
    while (now := time.monotonic()) < end:
        lines = []
        while due <= now:
            wheel = wheels[k % len(wheels)]
            ch = (wheel.address, wheel.motor)
            counters[ch] += 1
            vel = value_sequence(counters[ch], offsets[ch])
            sent[ch].append((time.monotonic(), expected_key(wheel, vel)))
            lines.append(f"base:{wheel.name}.vel=({vel})\n")
            due += period
            k += 1
        if lines:
            sock.sendall("".join(lines).encode())
        for s in tap.pump(due - time.monotonic(), [sock]):
            responses += s.recv(65536)
    t_stop = time.monotonic()
    # The tail: until every channel's last value is on the wire (newest wins), at most 1 s.
    settle_end = t_stop + 1.0
    while time.monotonic() < settle_end:
        if _all_final_seen(tap.packets[mark:], sent):
            break
        for s in tap.pump(0.01, [sock]):
            responses += s.recv(65536)
    responses += tap.idle(0.05, [sock])
    sock.sendall(b"base:base.stop=()\n")
    read_response(tap, sock)
    if b".error=(" in responses:
        raise RuntimeError(f"flood answered errors: {responses[:200]!r}")
    return _match(tap.packets[mark:], sent, start, t_stop, k)


def _all_final_seen(packets: list[tuple[float, int, int, int]],
                    sent: dict[tuple[int, int], list[tuple[float, Key]]]) -> bool:
    for cmds in sent.values():
        if not cmds:
            continue
        t_last, key = cmds[-1]
        if not any(t >= t_last and (a, c, d) == key for t, a, c, d in reversed(packets)):
            return False
    return True


def _match(packets: list[tuple[float, int, int, int]],
           sent: dict[tuple[int, int], list[tuple[float, Key]]],
           start: float, t_stop: float, total: int) -> dict[str, Any]:
    latency_us: list[float] = []
    lag_us: list[float] = []
    newest = 0
    matched = 0
    final_us: list[float] = []
    for ch, cmds in sent.items():
        last = -1  # index of the last command seen on the wire
        idx = -1  # index of the newest command sent before the packet
        final_seen: float | None = None
        for t, a, c, d in packets:
            if channel_of(a, c) != ch:
                continue
            while idx + 1 < len(cmds) and cmds[idx + 1][0] <= t:
                idx += 1
            for i in range(idx, last, -1):
                if cmds[i][1] == (a, c, d):
                    matched += 1
                    latency_us.append((t - cmds[i][0]) * 1e6)
                    lag_us.append((cmds[idx][0] - cmds[i][0]) * 1e6)
                    newest += i == idx
                    last = i
                    if i == len(cmds) - 1:
                        final_seen = t
                    break
        if cmds and final_seen is not None:
            final_us.append((final_seen - cmds[-1][0]) * 1e6)
    during = [p for p in packets if start <= p[0] <= t_stop]
    span = t_stop - start
    return {
        "commands_sent": total,
        "sent_per_s": round(total / span),
        "reached_wire_pct": round(100 * matched / total, 1) if total else None,
        "latency_us": summary(latency_us),
        "lag_behind_newest_us": summary(lag_us),
        "packets_carrying_newest_pct": round(100 * newest / matched, 1) if matched else None,
        "last_command_latency_us": summary(final_us),
        "packets_per_s": round(len(during) / span, 1),
        "bus_load_pct": round(100 * len(during) * PACKET_BITS / BAUD / span, 1),
    }


def measure(kind: str, settings: Settings, workdir: Path) -> dict[str, Any]:
    wheels = base_wheels()
    lf = next(w for w in wheels if w.name == "lf_wheel")
    workdir = workdir / kind
    workdir.mkdir(exist_ok=True)
    tap = WireTap(workdir)
    target = start_target(kind, tap, workdir, watchdog_timeout(settings.wd_timeout_s))
    try:
        with open_client(target) as sock:
            progress(f"command_to_wire: {kind}: {settings.c2w_singles} single commands")
            out: dict[str, Any] = {"single": singles(tap, sock, lf, settings.c2w_singles)}
            progress(f"command_to_wire: {kind}: flood of {settings.c2w_flood_hz:g}/s "
                     f"on lf_wheel, {settings.c2w_flood_s:g} s")
            out["flood_one_wheel"] = flood(tap, sock, [lf], settings.c2w_flood_hz,
                                           settings.c2w_flood_s)
            progress(f"command_to_wire: {kind}: flood of {settings.c2w_flood_hz:g}/s "
                     f"over 4 wheels, {settings.c2w_flood_s:g} s")
            out["flood_four_wheels"] = flood(tap, sock, wheels, settings.c2w_flood_hz,
                                             settings.c2w_flood_s)
        out["driver_stats"] = target.stop()
    finally:
        target.child.kill()
        tap.close()
    return out


def _flood_versus(fig: dict[str, Any], base: dict[str, Any]) -> dict[str, Any]:
    out = dict(fig)
    out["reached_wire_pct"] = compare(fig["reached_wire_pct"], base["reached_wire_pct"])
    out["latency_us"] = versus(fig["latency_us"], base["latency_us"])
    out["bus_load_pct"] = compare(fig["bus_load_pct"], base["bus_load_pct"])
    return out


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    results = {kind: measure(kind, settings, workdir) for kind in TARGETS}
    ramp, base = results["supervisor"], results["baseline"]
    rs, bs = ramp["single"], base["single"]
    stats = ramp["driver_stats"].get("base_motors", {})
    return {
        "baud": BAUD,
        "wire_ms_per_packet": round(1e3 * PACKET_BITS / BAUD, 2),
        "wire_packets_per_s": BAUD // PACKET_BITS,
        "baseline": {
            "what": "minimal relay: each MCP line straight to pyserial writes on the same "
                    "kind of pty, no pacing, no refresh",
            "single_wire_us": summary(bs["wire_us"]),
            "flood_one_wheel": base["flood_one_wheel"],
            "flood_four_wheels": base["flood_four_wheels"],
        },
        "single": {
            "commands": settings.c2w_singles,
            "missing": rs["missing"],
            "send_to_wire_us": versus(summary(rs["wire_us"]), summary(bs["wire_us"])),
            "response_us": versus(summary(rs["response_us"]), summary(bs["response_us"])),
        },
        "flood_one_wheel": _flood_versus(ramp["flood_one_wheel"], base["flood_one_wheel"]),
        "flood_four_wheels": _flood_versus(ramp["flood_four_wheels"],
                                           base["flood_four_wheels"]),
        "driver_max_pending": stats.get("max_pending"),
        "driver_stats": stats,
    }
