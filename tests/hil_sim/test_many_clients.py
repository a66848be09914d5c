"""More clients than `select` can watch, and a process out of file descriptors.

`select` cannot watch descriptor 1024 or above: with `max_clients: 1000`, clients landing
there were never answered and never cleaned up (`clients.count` stayed at 79 after all had
closed). With too few descriptors, `accept` failing with EMFILE looped 130,924 times in 10 s.
"""

from __future__ import annotations

import contextlib
import errno
import resource
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ramp.clock import MonotonicClock, VirtualClock
from ramp.hal.simio import SimBus
from ramp.runtime import build
from ramp.scheduler import Scheduler
from tests.harness import DEMO_YAML, MARTE_YAML, REPO, FakeWorld, config_from, end_process
from tests.harness import ask_line as ask

HOST = "127.0.0.1"


@contextlib.contextmanager
def fd_limit(soft: int) -> Iterator[None]:
    """This test process may open `soft` descriptors for a while."""
    old = resource.getrlimit(resource.RLIMIT_NOFILE)
    if old[1] != resource.RLIM_INFINITY and old[1] < soft:
        pytest.skip(f"the hard descriptor limit is {old[1]}")
    resource.setrlimit(resource.RLIMIT_NOFILE, (soft, old[1]))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, old)


def limit_child(soft: int, hard: int | None = None) -> Any:
    def apply() -> None:
        cur = resource.getrlimit(resource.RLIMIT_NOFILE)
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, cur[1] if hard is None else hard))
    return apply


def rows(sock: socket.socket) -> dict[str, str]:
    import re

    line = ask(sock, "robot:robot.get=()")
    return {f"{d}.{p}": v for d, p, v in re.findall(r"robot:(\w+)\.(\w+)=\(([^)]*)\)", line)}


@pytest.mark.timeout(90)
def test_eleven_hundred_clients_are_all_served_and_all_cleaned_up(tmp_path: Path) -> None:
    """`max_clients: 1100` in a process started with the usual soft limit of 1024: it raises
    its own limit, and the clients on descriptors past 1023 are answered and cleaned up."""
    cfg = tmp_path / "many.yaml"
    cfg.write_text(MARTE_YAML.replace("max_clients: 8", "max_clients: 1100"))
    with fd_limit(1500):
        proc = subprocess.Popen(
            [sys.executable, "-m", "ramp.cli", "run", "--sim", "--config", str(cfg),
             "--host", HOST, "--port", "0"], cwd=REPO, text=True, stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL, preexec_fn=limit_child(1024))
        clients: list[socket.socket] = []
        try:
            assert proc.stdout is not None
            port = int(proc.stdout.readline().strip().rsplit(":", 1)[1])
            monitor = socket.create_connection((HOST, port), timeout=10)
            for _ in range(1099):
                clients.append(socket.create_connection((HOST, port), timeout=10))
            deadline = time.monotonic() + 20
            while rows(monitor)["clients.count"] != "1100" and time.monotonic() < deadline:
                time.sleep(0.05)
            assert rows(monitor)["clients.count"] == "1100"
            server_fds = sorted(int(p.name) for p in Path(f"/proc/{proc.pid}/fd").iterdir())
            assert server_fds[-1] >= 1024  # some clients are where select cannot look
            for c in clients[-100:]:
                assert ask(c, "robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
            for c in clients:
                c.close()
            clients.clear()
            deadline = time.monotonic() + 20
            while rows(monitor)["clients.count"] != "1" and time.monotonic() < deadline:
                time.sleep(0.05)
            assert rows(monitor)["clients.count"] == "1"
            monitor.close()
        finally:
            for c in clients:
                c.close()
            end_process(proc)
    assert proc.returncode == 0


def test_max_clients_beyond_the_descriptor_limit_is_a_config_error(tmp_path: Path) -> None:
    cfg = tmp_path / "many.yaml"
    cfg.write_text(MARTE_YAML.replace("max_clients: 8", "max_clients: 1000"))
    proc = subprocess.run(
        [sys.executable, "-m", "ramp.cli", "run", "--sim", "--config", str(cfg), "--port", "0"],
        cwd=REPO, text=True, capture_output=True, timeout=30, preexec_fn=limit_child(256, 256))
    assert proc.returncode == 2, proc.stderr
    line = next(i for i, t in enumerate(MARTE_YAML.splitlines(), 1) if "max_clients" in t)
    assert proc.stderr.startswith(f"{cfg}:{line}: server.max_clients: 1000 clients need about")
    assert "may open at most 256" in proc.stderr


class OutOfDescriptors:
    """The listening socket, with `accept` failing as when the process has no descriptor
    left (the pending connection stays in the backlog, so the socket stays readable)."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.calls = 0
        self.failing = True

    def accept(self) -> tuple[socket.socket, Any]:
        self.calls += 1
        if self.failing:
            raise OSError(errno.EMFILE, "Too many open files")
        return self.sock.accept()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.sock, name)


@pytest.mark.timeout(30)
def test_emfile_on_accept_backs_off_instead_of_spinning(
        caplog: pytest.LogCaptureFixture) -> None:
    world = FakeWorld()
    sup = build(config_from(DEMO_YAML), MonotonicClock(), host=HOST, port=0,
                     bus_factory=lambda bc: SimBus(bc.name, dict(bc.params), world=world))
    sup.start()
    server = sup.server
    assert server.sock is not None
    wrapped = OutOfDescriptors(server.sock)
    server.sock = wrapped  # type: ignore[assignment]
    try:
        with socket.create_connection(server.address, timeout=5) as waiting:
            sup.scheduler.run_for(0.5)
            assert 1 <= wrapped.calls <= 8, wrapped.calls  # about one try per 100 ms
            assert caplog.text.count("accept failed") == 1
            wrapped.failing = False  # a descriptor is free again
            sup.scheduler.run_for(0.25)
            assert len(server.clients) == 1
            waiting.sendall(b"robot:robot.modules=()\n")
            sup.scheduler.run_for(0.05)
            assert waiting.recv(100) == b"robot:robot.modules=(demo,arm)\n"
    finally:
        server.sock = wrapped.sock
        sup.shutdown()


def test_the_wait_keeps_microsecond_precision_with_poll() -> None:
    """poll takes whole milliseconds and rounds up: the wait asks it for the whole
    milliseconds rounded down, and waits the rest in a microsecond select."""
    s = Scheduler(VirtualClock(), 100)
    a, b = socket.socketpair()
    s.add_reader(a.fileno(), lambda: None)
    asked: list[int] = []
    real = s._poller

    class Recording:
        def poll(self, ms: int) -> list[tuple[int, int]]:
            asked.append(ms)
            return real.poll(ms)

    s._poller = Recording()  # type: ignore[assignment]
    t0 = time.perf_counter()
    s._ready(0.0047)
    took = time.perf_counter() - t0
    s._ready(0.0006)
    assert asked[0] == 4  # never more than the time left
    assert asked[1:] == [0, 0]  # the sub-millisecond rest: poll(0), select, poll(0)
    assert took >= 0.004
    b.send(b"x")
    assert s._ready(0.0006) == ([a.fileno()], [])
    a.close()
    b.close()
