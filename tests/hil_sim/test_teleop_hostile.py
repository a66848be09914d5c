"""`ramp-teleop` as a process under hostile input on its page port (no robot needed).

- Every descriptor taken by idle connections: refused newcomers are logged once, not a
  traceback per attempt, and STOP from a page already open still answers at once.
- A binary WebSocket frame: the socket is closed with 1003 and a log line, no traceback.
"""

from __future__ import annotations

import json
import re
import resource
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from tests.harness import end_process

websockets_sync = pytest.importorskip("websockets.sync.client")

FD_LIMIT = 128


def _low_fd_limit() -> None:
    resource.setrlimit(resource.RLIMIT_NOFILE, (FD_LIMIT, FD_LIMIT))


class Teleop:
    def __init__(self) -> None:
        # No robot on port 1: the links retry in the background, the page works regardless.
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "ramp.teleop", "--backend", "127.0.0.1:1", "--http-port",
             "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            preexec_fn=_low_fd_limit)
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
        assert m, line
        self.port = int(m.group(1))

    def stop(self) -> str:
        _, err = end_process(self.proc, signal.SIGINT)
        return err


@pytest.fixture()
def teleop() -> Iterator[Teleop]:
    t = Teleop()
    try:
        yield t
    finally:
        if t.proc.poll() is None:
            t.proc.kill()
            t.proc.communicate(timeout=10)


def recv_until(ws: object, kind: str, timeout: float) -> dict[str, object]:
    end = time.monotonic() + timeout
    while True:
        msg = json.loads(ws.recv(timeout=max(0.01, end - time.monotonic())))  # type: ignore[attr-defined]
        if msg.get("type") == kind:
            return msg  # type: ignore[no-any-return]


def test_idle_connections_past_the_descriptor_limit_are_refused_quietly_and_stop_stays_fast(
        teleop: Teleop) -> None:
    url = f"ws://127.0.0.1:{teleop.port}/ws"
    with websockets_sync.connect(url, open_timeout=5) as ws:
        recv_until(ws, "hello", 5)
        idle = []
        for _ in range(FD_LIMIT + 72):
            try:
                idle.append(socket.create_connection(("127.0.0.1", teleop.port), timeout=2))
            except OSError:
                break
        time.sleep(1.0)  # the loop meets EMFILE on every accept it tries
        sent = time.monotonic()
        ws.send(json.dumps({"type": "stop"}))
        result = recv_until(ws, "result", 2)
        took = time.monotonic() - sent
        for s in idle:
            s.close()
    err = teleop.stop()
    assert result["id"] == "stop"  # "robot link down: STOP not sent", answered at once
    assert took < 0.05, f"STOP answered in {took:.3f} s"
    assert err.count("out of file descriptors") == 1, err[:2000]
    assert "Traceback" not in err, err[:2000]


def test_a_binary_frame_closes_the_page_socket_with_1003_and_a_log_line(
        teleop: Teleop) -> None:
    from websockets.exceptions import ConnectionClosed

    with websockets_sync.connect(f"ws://127.0.0.1:{teleop.port}/ws", open_timeout=5) as ws:
        recv_until(ws, "hello", 5)
        ws.send(b"\x00\x01binary")
        with pytest.raises(ConnectionClosed):
            while True:
                ws.recv(timeout=5)
        assert ws.close_code == 1003
    err = teleop.stop()
    assert "binary frame" in err
    assert "Traceback" not in err, err[:2000]
