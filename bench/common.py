"""What every benchmark shares: settings, statistics, child processes, configs, clients.

Child processes are the part that must never leak: each one is registered when started and
`kill_all` (called from `__main__` in a `finally`, and at exit) ends every one still running,
by its own pid.
"""

from __future__ import annotations

import atexit
import contextlib
import datetime as _dt
import functools
import math
import os
import platform
import re
import select
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import yaml

REPO = Path(__file__).resolve().parent.parent
MARTE_YAML = REPO / "ramp.yaml"
PYTHON = sys.executable
CLK_TCK = os.sysconf("SC_CLK_TCK")


def progress(msg: str) -> None:
    """Progress goes to stderr so stdout stays one JSON document."""
    print(f"bench: {msg}", file=sys.stderr, flush=True)


# -- settings -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Settings:
    """How long and how many: one profile for the full run, one quick, one for the smoke test."""

    profile: str
    tick_duration_s: float
    poll_clients: int
    poll_hz: float
    rt_requests: int
    rt_warmup: int
    tp_clients: tuple[int, ...]
    tp_in_flight: int
    tp_duration_s: float
    c2w_singles: int
    c2w_flood_hz: float
    c2w_flood_s: float
    wd_trials: int
    wd_timeout_s: float | None  # None: the timeout in ramp.yaml
    startup_runs: int
    rss_after_s: float
    #: Round trips: trials of each figure, interleaved with the baseline; the median is kept.
    rt_trials: int = 3
    #: Sequential round trips: trials (each `rt_requests` long), interleaved with the
    #: baseline's. This VM runs in phases (the same code's p50 moves by a third between
    #: them), so the ratio is also taken per pair of neighbouring trials.
    rt_seq_trials: int = 9

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


PROFILES = {
    "full": Settings("full", 60.0, 4, 50.0, 10_000, 500, (1, 4, 8), 16, 3.0,
                     500, 1000.0, 5.0, 10, None, 7, 60.0, 3),
    # Quick means under two minutes on a 2-core machine, every section included: one trial
    # of each figure (the full run keeps three and their median), short idle windows.
    "quick": Settings("quick", 1.5, 4, 50.0, 1_000, 100, (1, 4, 8), 16, 0.5,
                      100, 1000.0, 0.5, 1, None, 2, 2.0, 1, 3),
    # Minimal settings for tests/unit/test_bench_smoke.py: proves the code runs, not the figures.
    # The watchdog timeout keeps 10 heartbeat periods of margin: at 0.2 s a loaded machine
    # delayed a heartbeat enough to trip the watchdog (or the relay's) while still driving.
    "smoke": Settings("smoke", 0.4, 4, 50.0, 100, 10, (1, 4, 8), 16, 0.2,
                      8, 1000.0, 0.2, 1, 0.5, 1, 0.2, 1, 1),
}


# -- statistics ---------------------------------------------------------------------------------
def pick(data: Sequence[float], q: float) -> float:
    """Nearest-rank percentile of sorted `data` (the rule the scheduler's own stats use)."""
    return data[min(len(data) - 1, int(q * len(data)))]


def summary(values: Iterable[float], digits: int = 1) -> dict[str, Any]:
    """n, p50, p99, p99.9, max and mean of `values` (None when there are none)."""
    data = sorted(values)
    if not data:
        return {"n": 0, "p50": None, "p99": None, "p99_9": None, "max": None, "mean": None}
    return {
        "n": len(data),
        "p50": round(pick(data, 0.50), digits),
        "p99": round(pick(data, 0.99), digits),
        "p99_9": round(pick(data, 0.999), digits),
        "max": round(data[-1], digits),
        "mean": round(sum(data) / len(data), digits),
    }


def ratio(value: float | None, baseline: float | None) -> float | None:
    if value is None or baseline is None or baseline == 0 or not math.isfinite(baseline):
        return None
    return round(value / baseline, 2)


def compare(value: float | None, baseline: float | None) -> dict[str, Any]:
    """A figure beside its baseline and the ratio between them."""
    return {"value": value, "baseline": baseline, "ratio": ratio(value, baseline)}


def compare_keys(fig: dict[str, Any], base: dict[str, Any],
                 keys: Sequence[str] = ("p50", "p99", "p99_9", "max")) -> dict[str, Any]:
    return {k: compare(fig.get(k), base.get(k)) for k in keys}


# -- machine ------------------------------------------------------------------------------------
def machine_info() -> dict[str, Any]:
    model = ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    load = os.getloadavg()
    return {
        "cpu_model": model or platform.processor() or "unknown",
        "cores": os.cpu_count(),
        "usable_cores": len(os.sched_getaffinity(0)),
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "kernel": f"{platform.system()} {platform.release()}",
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        # The machine is shared: the load at the start says whether neighbours were busy.
        "loadavg_at_start": [round(x, 2) for x in load],
    }


# -- child processes ----------------------------------------------------------------------------
_CHILDREN: list[Child] = []


class ChildFailed(RuntimeError):
    """A child process died or did not say what it should have, with its log's tail."""


class Child:
    """A process we started: line protocol on its stdout, stderr into a log file."""

    def __init__(self, name: str, argv: Sequence[str], workdir: Path,
                 stdin: bool = False, cpu: int | None = None,
                 env: dict[str, str] | None = None) -> None:
        self.name = name
        self.log_path = workdir / f"{name}-{len(_CHILDREN)}.log"
        self._log = open(self.log_path, "wb")  # noqa: SIM115 - closed in wait()/kill()
        self.started_at = time.monotonic()
        self.proc = subprocess.Popen(
            list(argv), cwd=REPO, stdout=subprocess.PIPE, stderr=self._log,
            stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
            env=None if env is None else {**os.environ, **env},
            # Pinned before exec, so every thread the child starts inherits the core.
            preexec_fn=None if cpu is None else functools.partial(os.sched_setaffinity, 0, {cpu}))
        _CHILDREN.append(self)
        assert self.proc.stdout is not None
        self._fd = self.proc.stdout.fileno()
        self._buf = b""

    @property
    def pid(self) -> int:
        return self.proc.pid

    def running(self) -> bool:
        return self.proc.poll() is None

    def read_line(self, timeout: float) -> str:
        """The next stdout line; ChildFailed on timeout or exit (own buffer: select-safe)."""
        deadline = time.monotonic() + timeout
        while b"\n" not in self._buf:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise ChildFailed(f"{self.name}: no output within {timeout} s{self.tail()}")
            r, _, _ = select.select([self._fd], [], [], remaining)
            if r:
                chunk = os.read(self._fd, 65536)
                if not chunk:
                    self.proc.wait(timeout=5)
                    raise ChildFailed(f"{self.name} exited ({self.proc.returncode})"
                                      f"{self.tail()}")
                self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return line.decode(errors="replace")

    def expect(self, pattern: str, timeout: float = 30.0) -> re.Match[str]:
        """Read lines until one matches `pattern` (other lines are ignored)."""
        deadline = time.monotonic() + timeout
        while True:
            line = self.read_line(max(0.0, deadline - time.monotonic()))
            m = re.match(pattern, line)
            if m:
                return m

    def write_line(self, text: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(text.encode() + b"\n")
        self.proc.stdin.flush()

    def cpu_seconds(self) -> float:
        """utime + stime from /proc/PID/stat (all threads), in seconds."""
        stat = Path(f"/proc/{self.pid}/stat").read_text()
        fields = stat[stat.rindex(")") + 2:].split()
        return (int(fields[11]) + int(fields[12])) / CLK_TCK

    def status_kb(self, key: str) -> int | None:
        """A `kB` line of /proc/PID/status (VmRSS, VmHWM ...)."""
        with contextlib.suppress(OSError):
            for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
                if line.startswith(key + ":"):
                    return int(line.split()[1])
        return None

    def terminate(self, timeout: float = 10.0) -> int:
        """SIGTERM, wait; SIGKILL if it does not exit in time. Returns the exit code."""
        if self.running():
            self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired as exc:
            self.kill()
            raise ChildFailed(
                f"{self.name} ignored SIGTERM for {timeout} s{self.tail()}") from exc
        self._close()
        return code

    def kill(self) -> None:
        if self.running():
            self.proc.kill()
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(timeout=5)
        self._close()

    def _close(self) -> None:
        for f in (self.proc.stdout, self.proc.stdin):
            if f is not None:
                with contextlib.suppress(OSError):
                    f.close()
        self._log.close()

    def tail(self, n: int = 1500) -> str:
        with contextlib.suppress(OSError):
            self._log.flush()
            text = self.log_path.read_bytes()[-n:].decode(errors="replace")
            if text.strip():
                return f"; its log ends:\n{text}"
        return ""


def kill_all() -> None:
    """End every child still running (each by its own pid)."""
    for child in _CHILDREN:
        with contextlib.suppress(Exception):
            child.kill()
    _CHILDREN.clear()


atexit.register(kill_all)


def start_supervisor(name: str, config: Path, workdir: Path, timeout: float = 30.0,
                     cpu: int | None = None, real: bool = False,
                     env: dict[str, str] | None = None,
                     extra: Sequence[str] = ()) -> tuple[Child, int, Path]:
    """The supervisor as `ramp run --sim` (`real`: without `--sim`), watched by the bench's
    observer (bench.child); `extra`: more options of `bench.child supervisor` (`--record`).

    Returns the child, its MCP port and the file it writes its tick samples, task costs and
    driver statistics to when it exits."""
    dump = workdir / f"{name}-{len(_CHILDREN)}.json"
    child = Child(name, [PYTHON, "-m", "bench.child", "supervisor", "--config", str(config),
                         "--dump", str(dump), *(["--real"] if real else []), *extra], workdir,
                  cpu=cpu, env=env)
    try:
        m = child.expect(r"ramp: ready on ([\d.]+):(\d+)", timeout)
    except BaseException:
        child.kill()
        raise
    return child, int(m.group(2)), dump


def bench_cpu() -> int:
    """The core the round-trip figures pin client and servers to (the last one usable), as a
    probe running `taskset -c N` on every process would."""
    return max(os.sched_getaffinity(0))


@contextlib.contextmanager
def pinned(cpu: int) -> Iterator[None]:
    """This process (the benchmark's client) on `cpu` for the duration."""
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {cpu})
    try:
        yield
    finally:
        os.sched_setaffinity(0, before)


def median_of(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Per key, the median of the runs' values (numbers; other values from the first run)."""
    out: dict[str, Any] = {}
    for key, first in runs[0].items():
        values = [r[key] for r in runs if isinstance(r.get(key), int | float)]
        if isinstance(first, int | float) and not isinstance(first, bool) and values:
            mid = sorted(values)[len(values) // 2]
            out[key] = mid
        else:
            out[key] = first
    return out


# -- configs ------------------------------------------------------------------------------------
def load_marte() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(MARTE_YAML.read_text())
    return data


def write_config(workdir: Path, name: str, *, base_port: str | None = None,
                 watchdog_timeout: float | None = None,
                 ports: dict[str, str] | None = None, every_tick: bool = False) -> Path:
    """ramp.yaml served on 127.0.0.1:0; `base_port` makes base_motors a real driver on it
    (under --sim); `ports` moves buses to other ports (bus name -> port); `every_tick`: no
    idle ticks (`scheduler.idle_rate_hz` set to the base rate), every base period ticks."""
    data = load_marte()
    if every_tick:
        data["scheduler"]["idle_rate_hz"] = data["scheduler"]["rate_hz"]
    data["server"]["host"] = "127.0.0.1"
    data["server"]["port"] = 0
    if base_port is not None:
        data["buses"]["base_motors"].update(port=base_port, sim=False)
    for bus, port in (ports or {}).items():
        data["buses"][bus]["port"] = port
    if watchdog_timeout is not None:
        data["watchdog"]["timeout"] = watchdog_timeout
    path = workdir / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@dataclass(frozen=True)
class Wheel:
    """Where a base wheel is wired: what the bench expects to see on the Sabertooth wire."""

    name: str
    address: int
    motor: int
    polarity: int
    full_duty: float


@functools.cache
def base_wheels() -> tuple[Wheel, ...]:
    """Cached: parsing YAML takes milliseconds, which a timing loop must never spend."""
    base = load_marte()["modules"]["base"]
    return tuple(Wheel(n, int(d["address"]), int(d["motor"]), int(d.get("polarity", 1)),
                  float(d.get("full_duty", 1.0)))
            for n, d in base.items() if n.endswith("_wheel"))


# -- clients ------------------------------------------------------------------------------------
def connect(port: int, host: str = "127.0.0.1", timeout: float = 5.0) -> socket.socket:
    sock = socket.create_connection((host, port), timeout=timeout)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock


def ask(sock: socket.socket, text: str | bytes) -> bytes:
    """One message, one response line (blocking; client side only)."""
    data = text.encode() if isinstance(text, str) else text
    sock.sendall(data + b"\n")
    return recv_line(sock)


def recv_line(sock: socket.socket) -> bytes:
    """Read until the response line's newline (assumes one line in flight)."""
    buf = b""
    while not buf.endswith(b"\n"):
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError("server closed the connection")
        buf += chunk
    return buf


def robot_health(port: int) -> dict[str, Any]:
    """tick.late and tick.overruns as the supervisor itself reports them (robot.get)."""
    with connect(port) as sock:
        line = ask(sock, "robot:robot.get=()").decode()
    out: dict[str, Any] = {}
    m = re.search(r"robot:tick\.late=\((\d+),(\d+),(\d+)\)", line)
    if m:
        out["late_us_p50_p99_max"] = [int(g) for g in m.groups()]
    m = re.search(r"robot:tick\.overruns=\((\d+)\)", line)
    if m:
        out["overruns"] = int(m.group(1))
    return out


def versus(fig: dict[str, Any], base: dict[str, Any]) -> dict[str, Any]:
    """A `summary` whose percentiles each sit beside the baseline's (n stays a plain count)."""
    out: dict[str, Any] = {"n": fig.get("n"), "baseline_n": base.get("n")}
    out.update(compare_keys(fig, base, ("p50", "p99", "p99_9", "max", "mean")))
    return out
