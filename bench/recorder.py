"""`recorder`: what the flight recorder costs the tick, and what a slow disk does to it.

1. **Encoding on the tick**, per record kind: the time one `Recorder` call takes (encode the
   JSON payload, append it to the queue), median and p99 over batches of 100 calls, with
   the writer thread not yet running (so only the tick's own work is timed). Baseline: the
   work the supervisor already does for the same item in its tick, measured in the same
   run — parsing the request line (`parse_message`), formatting the response or get rows
   (`format_responses`), encoding the Sabertooth packet for a command (`encode_motor`),
   logging a line through a `logging.StreamHandler`. Then the writer's side: the writer
   is started and the time it takes to frame, compress and write everything queued, per
   record (it runs on its own thread, off the tick).
2. **The tick with the recorder on and off**: three processes run the real scheduler
   (`ramp.scheduler.Scheduler`, wall clock, 100 Hz) *at the same time* for the same window,
   each tick feeding a busy run's traffic — 4 MCP lines in and 4 out, 6 motor commands,
   and at 10 Hz `robot.get` and two modules' get rows (about 1,430 records/s): `off` skips
   the recorder calls (the baseline), `on` records to a file in the bench's work
   directory, `slow disk` records through a file whose writes crawl at `SLOW_DISK_BPS`, so
   the writer falls behind, the queue fills and records are dropped. Tick lateness
   p50/p99/p99.9/max, overruns, CPU % of a core (all threads), records written and dropped.
   Both recording runs use a queue of `QUEUE_RECORDS` records (the default is 20,000), so
   the slow disk fills it within the run. A fourth process, `crowded dir`, records into a
   directory already holding `CROWDED_FILES` files of earlier runs, with `keep: 1` and a
   new file every `CROWDED_MAX_MB` MB: rotation and pruning must not show in the tick
   (before the recorder kept its own list of files, each rotation listed the directory
   twice and the tick ran 142 ms late).
3. **`ramp run --sim` with and without `--record`**: three real supervisor processes
   (`bench.child supervisor`, the bench's observer keeping every tick's lateness and cost)
   run *at the same time* on the MARTE config while `SUP_CLIENTS` MCP clients per process
   drive and poll it at `SUP_HZ` (`base:base.drive=(60,0)base:base.get=()ble:ble.get=()`:
   a message in and out, four wheel commands, and the 10 Hz health and get samples, about
   1,200 records/s): `off` (the baseline), `on` (`--record DIR`), and `slow disk`
   (`--record DIR` on a disk throttled to `SLOW_DISK_BPS`, queue `QUEUE_RECORDS`). Tick
   lateness, what each tick's work costs (timed by the loop), CPU % of a core (every
   thread), and `robot:recorder.dropped` as `robot.get` reports it at the end.
"""

from __future__ import annotations

import argparse
import io
import json
import logging
import re
import statistics
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO, Any

from bench.common import (
    PYTHON,
    Child,
    Settings,
    compare,
    connect,
    progress,
    start_supervisor,
    summary,
    versus,
    write_config,
)

RATE_HZ = 100.0
SLOW_DISK_BPS = 4_000     # bytes/s: an SD card stalling on erase cycles, or worse
QUEUE_RECORDS = 2_000     # 1.4 s of this traffic
#: The crowded directory: files of earlier runs already there, the recorder keeping 1 and
#: rotating every CROWDED_MAX_MB (about every 0.7 s at this traffic).
CROWDED_FILES = 50_000
CROWDED_MAX_MB = 0.1
#: (tick run seconds, encode calls per kind, ramp run seconds) by profile
PROFILE = {"full": (30.0, 20_000, 30.0), "quick": (1.0, 2_000, 1.0),
           "smoke": (0.6, 200, 0.6)}
SUP_CLIENTS = 4
SUP_HZ = 50.0
SUP_MESSAGE = b"base:base.drive=(60,0)base:base.get=()ble:ble.get=()\n"
BATCH = 100


def _rows() -> dict[str, list[Any]]:
    from ramp.mcp.messages import Response

    health = [Response("robot", "robot", "uptime", (1234.567,)),
              Response("robot", "tick", "rate", (100.0,)),
              Response("robot", "tick", "late", (136, 188, 2162)),
              Response("robot", "tick", "overruns", (0,)),
              Response("robot", "watchdog", "timeout", (1.0,)),
              Response("robot", "watchdog", "state", ("armed",)),
              Response("robot", "control", "owner", ("operator",)),
              Response("robot", "clients", "count", (4,)),
              Response("robot", "base", "state", ("ok",)),
              Response("robot", "ble", "state", ("ok",))]
    base = [*(Response("base", w, "vel", (60,)) for w in
              ("lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel")),
            Response("base", "l_button", "press", (0,)),
            Response("base", "r_button", "press", (0,)),
            Response("base", "battery", "volt", (24.512,)),
            Response("base", "user_led", "on", (0,))]
    ble = [Response("ble", "lift", "vel", (0,)), Response("ble", "lift", "pos", (0.412,)),
           Response("ble", "chain", "vel", (80,)), Response("ble", "load", "kg", (12.25,))]
    return {"robot": health, "base": base, "ble": ble}


REQUEST = b"base:base.drive=(60,0)"
ANSWER_ROWS = "base"  # the answer line of a base.get: 177 bytes


# -- 1. encoding on the tick --------------------------------------------------------------------
def _per_call_ns(fn: Callable[[int], None], calls: int) -> dict[str, float]:
    """Median and p99 over batches of the mean ns per call."""
    means = []
    for start in range(0, calls, BATCH):
        t0 = time.perf_counter_ns()
        for i in range(start, start + BATCH):
            fn(i)
        means.append((time.perf_counter_ns() - t0) / BATCH)
    means.sort()
    return {"p50": round(statistics.median(means)), "p99": round(means[int(0.99 * len(means))])}


def encode_costs(workdir: Path, calls: int) -> dict[str, Any]:
    """Tick side with the writer not yet started (so its thread cannot interfere), then the
    writer's own cost: start it and time how long it takes to write everything queued."""
    from ramp.hal.sabertooth_codec import encode_motor
    from ramp.mcp.protocol import format_responses, parse_message
    from ramp.recorder import Recorder, RecorderConfig

    rows = _rows()
    answer = format_responses(rows[ANSWER_ROWS])
    rec = Recorder(RecorderConfig(str(workdir / "encode")), queue_records=1 << 30,
                   queue_bytes=1 << 40)
    rec.recording = True  # accept records before start(): the queue fills, nothing writes
    sink = logging.getLogger("bench.recorder.baseline")
    sink.propagate = False
    handler = logging.StreamHandler(io.StringIO())
    sink.addHandler(handler)
    client = "127.0.0.1:41234"
    kinds: dict[str, tuple[Callable[[int], None], Callable[[int], None], str]] = {
        "mcp_in": (lambda i: rec.mcp_in(i * 1e-3, client, REQUEST),
                   lambda i: parse_message(REQUEST), "parse_message of the request"),
        "mcp_out": (lambda i: rec.mcp_out(i * 1e-3, client, answer),
                    lambda i: format_responses(rows["base"]),
                    "format_responses of base.get's 8 rows"),
        "health": (lambda i: rec.health(i * 1e-3, rows["robot"]),
                   lambda i: format_responses(rows["robot"]),
                   "format_responses of robot.get's 10 rows"),
        "module_rows": (lambda i: rec.module_rows(i * 1e-3, "base", rows["base"]),
                        lambda i: format_responses(rows["base"]),
                        "format_responses of base.get's 8 rows"),
        "command": (lambda i: rec.command(i * 1e-3, "base_motors", "base.lf_wheel", 0.6),
                    lambda i: encode_motor(128, 1, 0.6), "Sabertooth encode_motor"),
        "event": (lambda i: rec.event(i * 1e-3, "watchdog_trip", "operator silent for 1.00 s"),
                  lambda i: sink.warning("watchdog expired: %s silent for %.2f s", client, 1.0),
                  "logging.warning to a StreamHandler"),
    }
    out: dict[str, Any] = {"calls_per_kind": calls}
    try:
        for kind, (record, baseline, what) in kinds.items():
            _per_call_ns(record, BATCH * 5)  # warm up (first-use schema, caches)
            value = _per_call_ns(record, calls)
            base = _per_call_ns(baseline, calls)
            out[kind] = {"baseline_is": what,
                         "ns_per_record": {k: compare(value[k], base[k]) for k in value}}
    finally:
        sink.removeHandler(handler)
    queued = rec.queued
    rec.recording = False
    t0, cpu0 = time.perf_counter(), time.process_time()
    rec.start(0.0)
    while rec.queued:
        time.sleep(0.001)  # this thread idles: the process's CPU is the writer's
    rec.close()
    elapsed, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    files = sorted((workdir / "encode").glob("*.mcap"))
    out["writer"] = {"records": rec.written, "of_queued": queued, "dropped": rec.dropped,
                     "us_per_record": round(elapsed / max(1, rec.written) * 1e6, 2),
                     "cpu_us_per_record": round(cpu / max(1, rec.written) * 1e6, 2),
                     "bytes_per_record": round(sum(f.stat().st_size for f in files)
                                               / max(1, rec.written), 1)}
    return out


# -- 2. the tick, on / off / slow disk ----------------------------------------------------------
class SlowFile:
    """A file on a disk that takes `bps` bytes a second: each write sleeps its share."""

    def __init__(self, path: Path, bps: float) -> None:
        self.f = open(path, "wb")  # noqa: SIM115 - closed with this object
        self.bps = bps

    def write(self, data: Any) -> int:
        time.sleep(len(data) / self.bps)
        return self.f.write(data)

    def tell(self) -> int:
        return self.f.tell()

    def flush(self) -> None:
        self.f.flush()

    def close(self) -> None:
        self.f.close()


def loop(args: argparse.Namespace) -> int:
    """Child: the scheduler at RATE_HZ feeding a busy run's records (or not)."""
    from ramp.clock import MonotonicClock
    from ramp.mcp.protocol import format_responses
    from ramp.recorder import Recorder, RecorderConfig
    from ramp.scheduler import Scheduler

    rows = _rows()
    answer = format_responses(rows[ANSWER_ROWS])
    clock = MonotonicClock()
    sched = Scheduler(clock, RATE_HZ)
    rec = None
    if args.mode != "off":
        opener: Callable[[Path], IO[bytes]] | None = None
        if args.mode == "slow":
            def opener(path: Path) -> IO[bytes]:
                return SlowFile(path, SLOW_DISK_BPS)  # type: ignore[return-value]
        config = RecorderConfig(args.dir)
        if args.mode == "crowded":
            d = Path(args.dir)
            d.mkdir(parents=True, exist_ok=True)
            for i in range(1, args.files + 1):
                (d / f"ramp-{i:06d}-20260101T000000Z.mcap").touch()
            config = RecorderConfig(args.dir, max_mb=CROWDED_MAX_MB, keep=1)
            # As `ramp run` does: its log on stderr, the first file opened by the writer.
            logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
        rec = Recorder(config, queue_records=QUEUE_RECORDS,
                       **({"opener": opener} if opener else {}))
        rec.start(clock.now(), wait_for_file=args.mode != "crowded")
    clients = [f"127.0.0.1:{41000 + k}" for k in range(4)]
    wheels = ("lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel")

    def traffic(now: float, dt: float) -> None:
        if rec is None:
            return
        for c in clients:
            rec.mcp_in(now, c, REQUEST)
            rec.mcp_out(now, c, answer)
        for w in wheels:
            rec.command(now, "base_motors", f"base.{w}", 0.6)
        rec.command(now, "ble_motors", "ble.chain_left", 0.8)
        rec.command(now, "ble_motors", "ble.lift_motor", -0.3)

    def sample(now: float, dt: float) -> None:
        if rec is None:
            return
        rec.health(now, rows["robot"])
        rec.module_rows(now, "base", rows["base"])
        rec.module_rows(now, "ble", rows["ble"])

    sched.add_task("traffic", RATE_HZ, traffic)
    sched.add_task("recorder", 10.0, sample)
    print("ready", flush=True)
    sys.stdin.readline()  # "go": every variant starts together
    cpu0 = time.process_time()
    t0 = time.monotonic()
    sched.run(lambda: clock.now() - t0 >= args.duration)
    cpu_s = time.process_time() - cpu0
    elapsed = time.monotonic() - t0
    stats = sched.stats
    late = list(stats.late_us)
    out = {"late_us": summary(late), "ticks": stats.ticks, "overruns": stats.overruns,
           "cpu_pct": round(100 * cpu_s / elapsed, 2), "elapsed_s": round(elapsed, 2)}
    if rec is not None:
        out.update(queued_at_end=rec.queued, dropped=rec.dropped)
        t_close = time.monotonic()
        rec.close(timeout=2.0)
        out.update(written=rec.written, close_s=round(time.monotonic() - t_close, 2),
                   dropped_after_close=rec.dropped,
                   files_left=sum(1 for _ in Path(args.dir).glob("ramp-*.mcap")))
    print(json.dumps(out), flush=True)
    return 0


def tick_runs(workdir: Path, duration: float) -> dict[str, Any]:
    children = {}
    crowded_files = CROWDED_FILES if duration >= 2 else 1_000  # the smoke run stays quick
    try:
        for mode in ("off", "on", "slow", "crowded"):
            d = workdir / f"rec-{mode}"
            children[mode] = Child(f"recorder-{mode}", [
                PYTHON, "-m", "bench.recorder", "--mode", mode, "--dir", str(d),
                "--duration", str(duration), "--files", str(crowded_files)], workdir,
                stdin=True)
        for child in children.values():
            child.expect("ready", 30)
        for child in children.values():
            child.write_line("go")
        results = {mode: json.loads(child.read_line(duration + 60))
                   for mode, child in children.items()}
    finally:
        for child in children.values():
            child.kill()
    off, on, slow, crowded = results["off"], results["on"], results["slow"], results["crowded"]
    files = sorted((workdir / "rec-on").glob("*.mcap"))
    out: dict[str, Any] = {"rate_hz": RATE_HZ, "duration_s": duration,
                           "records_per_s": round(on["written"] / on["elapsed_s"]),
                           "slow_disk_bytes_per_s": SLOW_DISK_BPS,
                           "queue_records": QUEUE_RECORDS}
    for label, r in (("on", on), ("slow_disk", slow), ("crowded_dir", crowded)):
        out[label] = {"late_us": versus(r["late_us"], off["late_us"]),
                      "overruns": compare(r["overruns"], off["overruns"]),
                      "cpu_pct": compare(r["cpu_pct"], off["cpu_pct"]),
                      "ticks": r["ticks"], "written": r["written"], "dropped": r["dropped"],
                      "queued_at_end": r["queued_at_end"], "close_s": r["close_s"]}
    out["crowded_dir"].update(files_before=crowded_files, keep=1, max_mb=CROWDED_MAX_MB,
                              files_left=crowded["files_left"])
    out["on"]["file_bytes"] = sum(f.stat().st_size for f in files)
    out["on"]["bytes_per_record"] = round(out["on"]["file_bytes"] / max(1, on["written"]), 1)
    return out


# -- 3. ramp run --sim, recording or not --------------------------------------------------------
def _dropped(port: int) -> int | None:
    """`robot:recorder.dropped=(n)` from robot.get (None: not recording)."""
    from bench.common import ask

    with connect(port) as sock:
        line = ask(sock, "robot:robot.get=()").decode()
    m = re.search(r"robot:recorder\.dropped=\((\d+)\)", line)
    return int(m.group(1)) if m else None


def supervisor_runs(workdir: Path, duration: float) -> dict[str, Any]:
    """Three `ramp run --sim` processes at once, each under the same MCP load."""
    from bench.tick import poll, tick_cost, window
    from ramp.recorder.reading import Recording
    from ramp.recorder.writer import recording_files

    config = write_config(workdir, "recorder-sup")
    modes = {"off": [], "on": ["--record", str(workdir / "sup-on")],
             "slow": ["--record", str(workdir / "sup-slow"), "--slow-disk", str(SLOW_DISK_BPS),
                      "--queue-records", str(QUEUE_RECORDS)]}
    started: dict[str, tuple[Child, int, Path]] = {}
    rtts: dict[str, list[float]] = {}
    try:
        for mode, extra in modes.items():
            started[mode] = start_supervisor(f"recorder-sup-{mode}", config, workdir,
                                             extra=extra)
        t0 = time.monotonic()
        cpu0 = {m: c.cpu_seconds() for m, (c, _, _) in started.items()}
        threads = [threading.Thread(target=lambda m=m, port=port: rtts.__setitem__(
            m, poll(port, SUP_CLIENTS, SUP_HZ, duration, SUP_MESSAGE)))
            for m, (_, port, _) in started.items()]
        for th in threads:
            th.start()
        for th in threads:
            th.join(duration + 60)
        t1 = time.monotonic()
        cpu1 = {m: c.cpu_seconds() for m, (c, _, _) in started.items()}
        dropped = {m: _dropped(port) for m, (_, port, _) in started.items()}
        for child, _, _ in started.values():
            child.terminate(20)
    finally:
        for child, _, _ in started.values():
            child.kill()
    runs: dict[str, dict[str, Any]] = {}
    for mode, (_, _, dump) in started.items():
        data = json.loads(dump.read_text())
        late, overruns = window(data["samples"], t0, t1)
        busy = summary(s[1] for s in data.get("busy", []) if t0 <= s[0] <= t1)
        runs[mode] = {"late_us": summary(late), "overruns": overruns,
                      "cpu_pct": round(100 * (cpu1[mode] - cpu0[mode]) / (t1 - t0), 2),
                      "busy_us": busy, "cost": tick_cost(data), "dropped": dropped[mode],
                      "rtt_us": summary(rtts.get(mode, []))}
    off = runs["off"]
    out: dict[str, Any] = {"duration_s": round(t1 - t0, 2), "clients": SUP_CLIENTS,
                           "hz_each": SUP_HZ, "message": SUP_MESSAGE.decode().strip(),
                           "slow_disk_bytes_per_s": SLOW_DISK_BPS,
                           "slow_queue_records": QUEUE_RECORDS,
                           "off": {"late_us": off["late_us"], "ticks": off["late_us"]["n"],
                                   "dropped": off["dropped"]}}
    for label, mode in (("on", "on"), ("slow_disk", "slow")):
        r = runs[mode]
        files = [p for _, p in recording_files(workdir / f"sup-{mode}")]
        messages = sum(1 for _ in Recording(files, progress=False)) if files else 0
        out[label] = {
            "late_us": versus(r["late_us"], off["late_us"]),
            "overruns": compare(r["overruns"], off["overruns"]),
            "cpu_pct": compare(r["cpu_pct"], off["cpu_pct"]),
            "tick_busy_us": {k: compare(r["busy_us"][k], off["busy_us"][k])
                             for k in ("p50", "p99", "mean")},
            "recorder_task_us": r["cost"]["tasks"].get("recorder"),
            "rtt_us_p50": compare(r["rtt_us"]["p50"], off["rtt_us"]["p50"]),
            "ticks": r["late_us"]["n"],
            "dropped": r["dropped"],
            "messages_in_files": messages,
            "file_bytes": sum(p.stat().st_size for p in files),
        }
    on = out["on"]
    on["records_per_s"] = round(on["messages_in_files"] / out["duration_s"])
    on["bytes_per_record"] = round(on["file_bytes"] / max(1, on["messages_in_files"]), 1)
    return out


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    duration, calls, sup_duration = PROFILE[settings.profile]
    progress(f"recorder: encoding cost, {calls} calls per kind")
    result: dict[str, Any] = {"encode": encode_costs(workdir, calls)}
    progress(f"recorder: tick with the recorder off / on / on a slow disk, {duration:g} s")
    result["tick"] = tick_runs(workdir, duration)
    progress(f"recorder: ramp run --sim without / with --record / on a slow disk, "
             f"{SUP_CLIENTS} clients each at {SUP_HZ:g} Hz, {sup_duration:g} s")
    result["ramp_run"] = supervisor_runs(workdir, sup_duration)
    return result


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.recorder")
    p.add_argument("--mode", choices=["off", "on", "slow", "crowded"], required=True)
    p.add_argument("--dir", required=True)
    p.add_argument("--duration", type=float, required=True)
    p.add_argument("--files", type=int, default=CROWDED_FILES,
                   help="files of earlier runs in the crowded directory")
    return loop(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
