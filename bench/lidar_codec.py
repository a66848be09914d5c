"""`lidar_codec`: decoding one full 1081-step SCIP scan (what the LIDAR driver does 40×/s).

The reply is a real-format MD scan of the UTM-30LX-EW, made by the emulator's own encoder
(firmware_like/hokuyo.py): echo, status, timestamp and 51 data lines of 64 characters, about
3.4 kB. Three figures, each per call, in µs:
- `decode_reply`: `scip.decode_reply` on the reply: every line's sum checked, 1081 ranges
  decoded (vectorised);
- `feed`: the streaming decoder finding the reply's end in a byte stream, then decoding it;
- `decode_to_scan`: `feed` plus building the `Scan` the perception code reads (metres, NaN
  mask);
- `emulator_scan`: the emulated sensor producing one MD scan (range source, encoding, sums),
  the cost the simulator pays per scan on top of its ray-caster.
Baseline, in the same loop: splitting the same reply into its lines and joining them again
(`b"".join(reply.split(b"\\n"))`), the least any decoder must do to touch every byte. Calls
of the two are interleaved so a busy moment hits both.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench.common import Settings, compare, compare_keys, progress, summary
from firmware_like.hokuyo import HokuyoSensor
from ramp.autonomy.hal import scip
from ramp.autonomy.hal.lidar import Scan, ScanGeometry

#: Calls measured per figure, by profile (a call takes tens of µs).
CALLS = {"full": 50_000, "quick": 5_000, "smoke": 200}
SCANS_PER_S = 40  # a UTM-30LX-EW streams at 2400 rpm


def one_md_reply() -> bytes:
    """One whole MD scan reply as the emulated sensor sends it."""
    sensor = HokuyoSensor(now=0.0)
    sensor.feed(0.001, b"MD0000108001000\n")
    sensor.service(0.05)
    out = sensor.take_output()
    replies = out.split(b"\n\n")
    return replies[1] + b"\n\n"  # [0] is the MD acknowledgement


def _time_pair(fn: Callable[[], object], base: Callable[[], object],
               calls: int) -> tuple[list[float], list[float]]:
    values: list[float] = []
    baseline: list[float] = []
    clock = time.perf_counter_ns
    for _ in range(min(100, calls)):  # warm caches and numpy's dispatch
        fn()
        base()
    for _ in range(calls):
        t0 = clock()
        fn()
        t1 = clock()
        base()
        t2 = clock()
        values.append((t1 - t0) / 1e3)
        baseline.append((t2 - t1) / 1e3)
    return values, baseline


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    calls = CALLS.get(settings.profile, CALLS["quick"])
    reply = one_md_reply()
    block = reply[:-1]  # decode_reply takes the reply without its final empty line
    decoded = scip.decode_reply(block)
    assert isinstance(decoded, scip.Reply) and decoded.values is not None
    assert len(decoded.values) == 1081
    geometry = ScanGeometry()
    decoder = scip.ScipDecoder()

    def baseline() -> bytes:
        return b"".join(reply.split(b"\n"))

    def feed() -> object:
        return decoder.feed(reply)[0]

    def to_scan() -> Scan:
        r = decoder.feed(reply)[0]
        assert isinstance(r, scip.Reply) and r.values is not None
        return Scan.from_raw(r.values, geometry, sensor_time=0.0, received_at=0.0)

    sensor = HokuyoSensor(now=0.0)
    sensor.feed(0.0, b"MD0000108001000\n")
    sensor.service(0.05)
    sensor.take_output()
    period = sensor.period
    tick = [0.05]

    def emulator_scan() -> bytes:
        tick[0] += period
        sensor.service(tick[0])
        return sensor.take_output()

    figures: dict[str, Any] = {
        "reply_bytes": len(reply),
        "steps": len(decoded.values),
        "data_lines": reply.count(b"\n") - 4,
        "calls": calls,
    }
    for name, fn in (("decode_reply_us", lambda: scip.decode_reply(block)),
                     ("feed_us", feed), ("decode_to_scan_us", to_scan),
                     ("emulator_scan_us", emulator_scan)):
        progress(f"lidar_codec: {calls} calls of {name[:-3]} beside the baseline")
        values, base = _time_pair(fn, baseline, calls)
        figures[name] = compare_keys(summary(values, 2), summary(base, 2),
                                     ("p50", "p99", "max", "mean"))
    p50 = figures["decode_to_scan_us"]["p50"]
    figures["cpu_pct_at_40_scans_per_s"] = compare(
        round(SCANS_PER_S * p50["value"] / 1e4, 3), round(SCANS_PER_S * p50["baseline"] / 1e4, 3))
    return figures
