"""Processes the benchmarks start: `python -m bench.child NAME ...`.

- `supervisor`: exactly `ramp run --sim` (it calls `ramp.cli.main`; `--real` leaves out
  `--sim`, `--record DIR` records, `--fake-phidget22` puts the tests' fake of the vendor
  library in place of `Phidget22`, live: `tests/fake_phidget22.serve`) with an observer
  (`ramp.runtime.Observer`) that keeps every tick's lateness with its time and, at shutdown,
  each driver's `stats` and each task's cost; all of it is written to `--dump` as JSON when
  the process exits (after SIGTERM).
  `--slow-disk BPS` gives the recorder a disk whose writes take BPS bytes a second
  (`bench.recorder.SlowFile`) and a queue of `--queue-records` records.
- `select-loop`: the tick baseline, a bare absolute-deadline loop waiting in `select.select`,
  run beside the supervisor until told to stop.
- `bare-server`: the round-trip baseline, a minimal `select.select` server answering every
  line with a fixed response of the supervisor's size.
- `relay`: the wire baseline, a minimal TCP-line to Sabertooth-packet relay with a watchdog,
  writing through pyserial to the same pty the supervisor's driver would use.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import select
import signal
import socket
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any


# -- supervisor ---------------------------------------------------------------------------------
def supervisor(args: argparse.Namespace) -> int:
    """`ramp run --sim` (through `ramp.cli.main`), watched by an observer: the runtime's own
    hook points (`ramp.runtime.observers`), nothing replaced from outside."""
    import ramp.cli
    from ramp.runtime import Observer, Supervisor

    samples: list[tuple[float, float, int]] = []
    busy: list[tuple[float, float]] = []
    at_exit: dict[str, object] = {}

    class BenchObserver(Observer):
        """Every tick's lateness and cost with its time; at shutdown, the drivers' counters
        and what each task cost (neither is exposed over MCP)."""

        sup: Supervisor | None = None

        def started(self, supervisor: Supervisor) -> None:
            self.sup = supervisor

        def tick(self, t: float, late_s: float) -> None:
            overruns = self.sup.scheduler.stats.overruns if self.sup is not None else 0
            samples.append((time.monotonic(), late_s * 1e6, overruns))

        def tick_done(self, t: float, busy_s: float) -> None:
            busy.append((time.monotonic(), busy_s * 1e6))

        def stopping(self, supervisor: Supervisor) -> None:
            at_exit["bus_stats"] = {name: dict(bus.stats) for name, bus in
                                    supervisor.buses.items()
                                    if isinstance(getattr(bus, "stats", None), dict)}
            at_exit["tasks"] = {t.name: {"runs": t.runs, "total_s": t.total_s, "max_s": t.max_s}
                                for t in supervisor.scheduler.tasks}
            at_exit["ticks"] = supervisor.scheduler.stats.ticks

    argv = ["run", "--config", args.config, "--host", "127.0.0.1", "--port", "0",
            "--log-level", args.log_level]
    if not args.real:
        argv.append("--sim")
    if args.record:
        argv += ["--record", args.record]
    if args.fake_phidget22:
        _fake_phidget22()
    if args.slow_disk:
        _slow_disk(args.slow_disk, args.queue_records)
    code = ramp.cli.main(argv, observer=BenchObserver())
    Path(args.dump).write_text(json.dumps({"exit": code, "samples": samples, "busy": busy,
                                           **at_exit}))
    return code


#: The fake Phidget22 library's steady readings: a 20.5 V rail through a 1135 sensor on
#: channel 0, a lift pot at mid stroke on the others, an empty bin's bridge ratio (V/V).
FAKE_VOLTS = {0: 2.5 + 0.0681 * 20.5}
FAKE_DEFAULT_VOLTS = 2.5
FAKE_RATIO = 0.25e-3


def _fake_phidget22() -> None:
    from tests.fake_phidget22 import serve

    serve(FAKE_VOLTS, FAKE_DEFAULT_VOLTS, FAKE_RATIO)


def _slow_disk(bytes_per_s: float, queue_records: int) -> None:
    """The recorder `ramp run` builds (`ramp.runtime.recording.recorder_for`, looked up when
    `ramp run` starts) gets a throttled disk and a short queue, so it falls behind within the
    run; everything else is `ramp run --record` as it is."""
    import ramp.runtime.recording as recording
    from bench.recorder import SlowFile
    from ramp.recorder import Recorder

    made = recording.recorder_for

    def recorder_for(*args: Any, **kwargs: Any) -> Recorder | None:
        rec = made(*args, **kwargs)
        if rec is None:
            return None
        return Recorder(rec.config, queue_records=queue_records,
                        opener=lambda path: SlowFile(path, bytes_per_s))  # type: ignore[arg-type,return-value]

    recording.recorder_for = recorder_for  # type: ignore[assignment]


# -- select loop (tick baseline) ----------------------------------------------------------------
def _wait_until(deadline: float, fd: int) -> bool:
    """Wait for `deadline` in select with a µs timeout; False when `fd` became readable."""
    while True:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return True
        readable, _, _ = select.select([fd], [], [], remaining)
        if readable:
            return False


def select_loop(args: argparse.Namespace) -> int:
    """Same deadline rule as the scheduler (missed ticks skipped), doing nothing per tick.

    Like the supervisor's loop it waits in `select` on one descriptor (stdin here, its
    listening socket there); a line on stdin ends the loop, then every (time, lateness µs)
    sample is printed as one JSON line, so the parent can cut the same window it measured
    the supervisor in."""
    period = 1.0 / args.rate
    samples: list[tuple[float, float]] = []
    stdin = sys.stdin.fileno()
    print("start", flush=True)
    deadline = time.monotonic() + period
    while _wait_until(deadline, stdin):
        now = time.monotonic()
        late = now - deadline
        samples.append((now, late * 1e6))
        deadline += (1 + int(late // period)) * period
    sys.stdin.readline()
    print(json.dumps({"samples": samples}), flush=True)
    return 0


# -- bare server (round-trip baseline) ----------------------------------------------------------
def bare_server(args: argparse.Namespace) -> int:
    """Each complete line in is answered by one fixed line of `--size` bytes (with `\\n`).

    The least a Python line server can do: one `select.select` over its sockets, `recv`,
    count newlines, `send`. No parsing, no routing, no formatting, so the ratio against it is
    what RAMP's own work costs per request."""
    answer = b"x" * (args.size - 1) + b"\n"
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 0))
    server.listen(64)
    server.setblocking(False)
    out: dict[socket.socket, bytearray] = {}
    stop = False

    def on_term(signum: int, frame: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, on_term)
    print(f"ready on 127.0.0.1:{server.getsockname()[1]}", flush=True)

    def drop(sock: socket.socket) -> None:
        out.pop(sock, None)
        sock.close()

    while not stop:
        waiting = [s for s, buf in out.items() if buf]
        try:
            readable, writable, _ = select.select([server, *out], waiting, [], 0.5)
        except InterruptedError:
            continue
        for sock in readable:
            if sock is server:
                try:
                    conn, _ = server.accept()
                except BlockingIOError:
                    continue
                conn.setblocking(False)
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                out[conn] = bytearray()
                continue
            try:
                data = sock.recv(65536)
            except BlockingIOError:
                continue
            except OSError:
                data = b""
            if not data:
                drop(sock)
                continue
            out[sock] += answer * data.count(b"\n")
            writable.append(sock)
        for sock in writable:
            buf = out.get(sock)
            if not buf:
                continue
            try:
                n = sock.send(buf)
            except BlockingIOError:
                continue
            except OSError:
                drop(sock)
                continue
            del buf[:n]
    return 0


# -- relay (wire baseline) ----------------------------------------------------------------------
_REQUEST = re.compile(rb"(\w+):(\w+)\.(\w+)=\(([^)]*)\)")


def relay(args: argparse.Namespace) -> int:
    """TCP lines -> Sabertooth packets, straight through: no pacing, no refresh, no routing
    table beyond the four wheels, and a watchdog that is a select timeout."""
    import serial

    from ramp.hal.sabertooth_codec import encode_motor

    wheels: dict[str, tuple[int, int, int, float]] = {
        w["name"]: (w["address"], w["motor"], w["polarity"], w["full_duty"])
        for w in json.loads(args.wheels)}
    ser = serial.serial_for_url(args.port, baudrate=args.baud, timeout=0)
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    stop = False

    def on_term(signum: int, frame: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, on_term)
    print(f"ready on 127.0.0.1:{server.getsockname()[1]}", flush=True)
    clients: dict[socket.socket, bytes] = {}
    armed_by: socket.socket | None = None
    fed_at = 0.0

    def packet(name: str, vel: float) -> bytes:
        address, motor, polarity, full = wheels[name]
        duty = max(-1.0, min(1.0, polarity * vel / 100.0 * full))
        return encode_motor(address, motor, duty)

    def zeros() -> bytes:
        return b"".join(packet(n, 0) for n in wheels)

    def handle(sock: socket.socket, line: bytes) -> None:
        nonlocal armed_by, fed_at
        if sock is armed_by:
            fed_at = time.monotonic()
        out = b""
        moving: bool | None = None
        for m in _REQUEST.finditer(line):
            device, function = m.group(2).decode(), m.group(3)
            params = [p.strip() for p in m.group(4).split(b",") if p.strip()]
            if device in wheels and function == b"vel":
                v = int(params[0])
                out += packet(device, v)
                moving = v != 0
            elif device == "base" and function == b"drive":
                s, d = float(params[0]), math.radians(float(params[1]))
                left, right = s * (math.cos(d) + math.sin(d)), s * (math.cos(d) - math.sin(d))
                scale = abs(s) / max(abs(left), abs(right)) if max(abs(left), abs(right)) else 0
                for n in wheels:
                    out += packet(n, round((left if n[0] == "l" else right) * scale))
                moving = s != 0
            elif device == "base" and function == b"stop":
                out += zeros()
                moving = False
        if out:
            ser.write(out)
        if moving is True:
            armed_by, fed_at = sock, time.monotonic()
        elif moving is False:
            armed_by = None
        sock.sendall(b"\n")

    while not stop:
        timeout = 0.5 if armed_by is None else max(0.0, fed_at + args.timeout - time.monotonic())
        r, _, _ = select.select([server, *clients], [], [], timeout)
        if armed_by is not None and time.monotonic() - fed_at >= args.timeout:
            ser.write(zeros())
            armed_by = None
        for sock in r:
            if sock is server:
                conn, _ = server.accept()
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                clients[conn] = b""
                continue
            try:
                data = sock.recv(65536)
            except OSError:
                data = b""
            if not data:
                del clients[sock]
                sock.close()
                if sock is armed_by:
                    ser.write(zeros())
                    armed_by = None
                continue
            buf = clients[sock] + data
            *lines, clients[sock] = buf.split(b"\n")
            for line in lines:
                handle(sock, line)
    ser.close()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.child")
    sub = parser.add_subparsers(dest="what", required=True)
    p = sub.add_parser("supervisor")
    p.add_argument("--config", required=True)
    p.add_argument("--dump", required=True)
    p.add_argument("--log-level", default="warning")
    p.add_argument("--real", action="store_true", help="real drivers: no --sim")
    p.add_argument("--record", default="", help="ramp run --record DIR")
    p.add_argument("--fake-phidget22", action="store_true",
                   help="the tests' fake Phidget22 library, live (tests/fake_phidget22.py)")
    p.add_argument("--slow-disk", type=float, default=0.0,
                   help="the recorder's disk takes this many bytes a second")
    p.add_argument("--queue-records", type=int, default=20_000,
                   help="with --slow-disk: the recorder's queue, in records")
    p.set_defaults(func=supervisor)
    p = sub.add_parser("select-loop")
    p.add_argument("--rate", type=float, required=True)
    p.set_defaults(func=select_loop)
    p = sub.add_parser("bare-server")
    p.add_argument("--size", type=int, required=True)
    p.set_defaults(func=bare_server)
    p = sub.add_parser("relay")
    p.add_argument("--port", required=True)
    p.add_argument("--baud", type=int, default=9600)
    p.add_argument("--timeout", type=float, required=True)
    p.add_argument("--wheels", required=True, help="JSON list of wheel wiring")
    p.set_defaults(func=relay)
    args = parser.parse_args(argv)
    code: int = args.func(args)
    return code


if __name__ == "__main__":
    sys.exit(main())
