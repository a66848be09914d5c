"""Connection abuse against a real `ramp run --sim --port 0` process (issue 5, part 3).

Everything on 127.0.0.1. Connect/disconnect storms must leak no file descriptor and no
memory; clients that never read are dropped at their output bound; a flood or a client
trickling one byte at a time never blocks the loop (another client's round trips stay fast,
tick lateness stays in its idle band, the stall guard never fires); extra clients get `busy`;
a half-closed client still gets its answers and counts as gone for the watchdog.
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import signal
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
HOST = "127.0.0.1"

pytestmark = pytest.mark.timeout(60)


class Ramp:
    """A `ramp run --sim` child process, its log in a file so a chatty log never blocks it."""

    def __init__(self, log_path: Path) -> None:
        self.log_path = log_path
        self._log = log_path.open("w")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "ramp.cli", "run", "--sim", "--host", HOST, "--port", "0"],
            cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=self._log)
        assert self.proc.stdout is not None
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            r, _, _ = select.select([self.proc.stdout], [], [], 0.5)
            if r:
                line = self.proc.stdout.readline()
                m = re.match(r"ramp: ready on ([\d.]+):(\d+)", line)
                if m:
                    self.port = int(m.group(2))
                    return
                if not line:
                    break
        self.proc.kill()
        raise AssertionError(f"no ready line; log: {self.log()}")

    def log(self) -> str:
        return self.log_path.read_text()

    def fds(self) -> int:
        return len(os.listdir(f"/proc/{self.proc.pid}/fd"))

    def rss_kb(self) -> int:
        status = Path(f"/proc/{self.proc.pid}/status").read_text()
        m = re.search(r"VmRSS:\s+(\d+) kB", status)
        assert m
        return int(m.group(1))

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        assert self.proc.returncode == 0, self.log()[-2000:]


class Mcp:
    """A blocking line client with a deadline on every read."""

    def __init__(self, port: int, timeout: float = 10.0) -> None:
        self.sock = socket.create_connection((HOST, port), timeout=timeout)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buf = b""

    def line(self) -> str:
        while b"\n" not in self.buf:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed by the server")
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return line.decode()

    def ask(self, text: str) -> str:
        self.sock.sendall(text.encode() + b"\n")
        return self.line()

    def close(self) -> None:
        self.sock.close()


def health(c: Mcp) -> dict[str, str]:
    """robot.get rows as {"tick.late": "p50,p99,max", ...}."""
    line = c.ask("robot:robot.get=()")
    return {f"{d}.{p}": v for d, p, v in re.findall(r"robot:(\w+)\.(\w+)=\(([^)]*)\)", line)}


def late_us(c: Mcp) -> tuple[int, int, int]:
    p50, p99, mx = (int(x) for x in health(c)["tick.late"].split(","))
    return p50, p99, mx


def wait_clients(c: Mcp, n: int, seconds: float = 5.0) -> None:
    """Until the server counts `n` clients (disconnects are noticed on the next read)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if health(c)["clients.count"] == str(n):
            return
        time.sleep(0.02)
    raise AssertionError(f"clients.count stayed {health(c)['clients.count']}, wanted {n}")


@pytest.fixture(scope="module")
def ramp(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Ramp]:
    r = Ramp(tmp_path_factory.mktemp("abuse") / "ramp.log")
    try:
        yield r
    finally:
        r.stop()
    assert "tick loop stalled" not in r.log()


@pytest.fixture
def monitor(ramp: Ramp) -> Iterator[Mcp]:
    c = Mcp(ramp.port)
    assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
    wait_clients(c, 1)
    yield c
    c.close()


def settled_fds(ramp: Ramp, monitor: Mcp) -> int:
    """The server's fd count once it stops changing: the last connections of a burst may
    still sit in the listen backlog or be closing. A leak settles high; a straggler goes."""
    last = ramp.fds()
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        monitor.ask("")
        time.sleep(0.1)
        now = ramp.fds()
        if now == last:
            return now
        last = now
    return last


def test_connect_disconnect_cycles_leak_no_fd_and_no_memory(ramp: Ramp, monitor: Mcp) -> None:
    def cycle(i: int) -> None:
        s = socket.create_connection((HOST, ramp.port), timeout=10)
        kind = i % 4
        if kind == 1:  # a full round trip
            s.sendall(b"robot:robot.modules=()\n")
            buf = b""
            while not buf.endswith(b"\n"):
                buf += s.recv(4096)
            assert buf == b"robot:robot.modules=(base,ble)\n"
        elif kind == 2:  # hang up in the middle of a message
            s.sendall(b"base:base.drive=(10,")
        elif kind == 3:  # reset instead of a clean close
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        s.close()

    for i in range(100):  # warm-up: first-use allocations are not a leak
        cycle(i)
    wait_clients(monitor, 1)
    fds0, rss0 = settled_fds(ramp, monitor), ramp.rss_kb()
    for i in range(1000):
        cycle(i)
    wait_clients(monitor, 1)
    assert settled_fds(ramp, monitor) <= fds0  # no growth: every closed socket was released
    assert ramp.rss_kb() - rss0 < 2048, (rss0, ramp.rss_kb())
    assert monitor.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"


def test_flood_never_stalls_the_loop(ramp: Ramp, monitor: Mcp) -> None:
    """256 KiB of bare newlines, answered in full, while another client asks: found here, one
    64 KiB read used to hold the loop for 300 ms and the stall guard stopped every motor."""
    flood = Mcp(ramp.port)
    flood.sock.setblocking(False)
    data = b"\n" * (256 * 1024)
    sent = received = 0
    rtts: list[float] = []
    deadline = time.monotonic() + 30
    while received < len(data) and time.monotonic() < deadline:
        if sent < len(data):
            with contextlib.suppress(BlockingIOError):
                sent += flood.sock.send(data[sent:sent + 65536])
        try:
            chunk = flood.sock.recv(1 << 20)
            assert chunk, "the flooding client was dropped though it reads its answers"
            assert chunk.count(b"\n") == len(chunk)
            received += len(chunk)
        except BlockingIOError:
            select.select([flood.sock], [], [], 0.002)
        if len(rtts) < 200 and received // 4096 > len(rtts):
            t = time.monotonic()
            assert monitor.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
            rtts.append(time.monotonic() - t)
    assert received == len(data)
    flood.close()
    assert max(rtts) < 0.5, max(rtts)
    _, _, worst = late_us(monitor)
    assert worst < 200_000, f"a tick was {worst} us late during the flood"
    assert "tick loop stalled" not in ramp.log()


def test_non_readers_are_dropped_and_others_keep_working(ramp: Ramp, monitor: Mcp) -> None:
    hogs = []
    for _ in range(2):
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        s.connect((HOST, ramp.port))
        s.setblocking(False)
        hogs.append(s)
    wait_clients(monitor, 3)
    ask = b"base:base.describe=()" * 150 + b"\n"
    alive = set(range(len(hogs)))
    deadline = time.monotonic() + 30
    checks = 0
    while alive and time.monotonic() < deadline:
        for i in list(alive):
            try:
                hogs[i].send(ask)
            except BlockingIOError:
                select.select([], [], [], 0.001)
            except OSError:  # reset or broken pipe: the server hung up on it
                alive.discard(i)
        checks += 1
        if checks % 20 == 0:
            t = time.monotonic()
            assert monitor.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
            assert time.monotonic() - t < 0.5
            if health(monitor)["clients.count"] == "1":
                break  # both dropped; our own sends have not noticed yet
    for s in hogs:
        s.close()
    wait_clients(monitor, 1)
    assert ramp.log().count("not reading its responses") >= 2
    assert "base:base.function=(drive" in monitor.ask("base:base.describe=()")


def test_more_clients_than_max_clients_get_busy(ramp: Ramp, monitor: Mcp) -> None:
    others = [Mcp(ramp.port) for _ in range(7)]  # with the monitor: max_clients (8)
    wait_clients(monitor, 8)
    for i in range(5):
        extra = Mcp(ramp.port)
        if i % 2:
            extra.sock.sendall(b"robot:robot.modules=()\n")  # talks before it reads
        assert extra.line() == "robot:mcp.error=(busy,too many clients; at most 8)"
        with pytest.raises(ConnectionError):
            extra.line()
        extra.close()
    for c in [monitor, *others]:
        assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
    others.pop().close()
    wait_clients(monitor, 7)
    late = Mcp(ramp.port)
    assert late.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
    for c in [late, *others]:
        c.close()
    wait_clients(monitor, 1)


def test_half_closed_client_gets_its_answers_and_stops_its_motion(ramp: Ramp,
                                                                   monitor: Mcp) -> None:
    c = Mcp(ramp.port)
    n = 500
    c.sock.sendall(b"base:base.drive=(40,0)\nbase:base.get=()\n"
                   + b"base:base.describe=()\n" * n + b"robot:robot.modules=()\n")
    c.sock.shutdown(socket.SHUT_WR)
    assert c.line() == ""
    assert "base:lf_wheel.vel=(40)" in c.line()
    for _ in range(n):
        assert c.line().startswith("base:base.function=(get)")
    assert c.line() == "robot:robot.modules=(base,ble)"
    with pytest.raises(ConnectionError):
        c.line()  # then the server closes its side
    c.close()
    wait_clients(monitor, 1)
    rows = health(monitor)
    assert rows["watchdog.state"] == "tripped"  # its sender hung up while the base moved
    assert "base:lf_wheel.vel=(0)" in monitor.ask("base:base.get=()")


def test_slow_byte_client_never_blocks_the_loop(tmp_path: Path) -> None:
    """One byte every 0.2 s for 2 s, against a fresh process so the lateness window holds only
    this test: the other client's round trips stay fast and tick.late p99 stays in the band
    measured idle a moment before (a generous factor: this must not flake on a busy host)."""
    r = Ramp(tmp_path / "ramp.log")
    try:
        other = Mcp(r.port)
        time.sleep(1.0)
        _, idle_p99, _ = late_us(other)
        slow = Mcp(r.port)
        slow.sock.sendall(b"robot:robot.m")
        rtts = []
        for byte in b"odules=()\n":
            time.sleep(0.2)
            slow.sock.send(bytes([byte]))
            t = time.monotonic()
            assert other.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
            rtts.append(time.monotonic() - t)
        assert slow.line() == "robot:robot.modules=(base,ble)"
        _, busy_p99, _ = late_us(other)
        assert max(rtts) < 0.25, rtts
        assert busy_p99 <= 4 * idle_p99 + 5000, (idle_p99, busy_p99)
        slow.close()
        other.close()
    finally:
        r.stop()
    assert "tick loop stalled" not in r.log()
