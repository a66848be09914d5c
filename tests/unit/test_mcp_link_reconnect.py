"""The autonomy's MCP link across a lost connection (issue 19 item 7), against a backend the
test plays by hand on real TCP: every reconnect starts from a clean slate, a callback run by
the close cannot send into it, and `RobotLink.send`'s `on_done` tells failure from success.

Before: the pending callbacks ran while the link still read CONNECTED, so one that sent
(the executive re-asking, a stop) wrote into the dead connection's buffer; the reconnect
dropped its callback without a word and sent its bytes first on the new connection, where
they were paired with the reply meant for the next request. `on_done` fired on failures too,
so `AcquireControl` took a lost acquire for an acquired robot."""

from __future__ import annotations

import socket
from collections.abc import Iterator
from typing import Any

import pytest

from ramp.autonomy.executive.robot import RobotLink
from ramp.autonomy.mcp_link import CONNECTED, DISCONNECTED, STOPPED, McpLink
from ramp.clock import VirtualClock
from ramp.mcp.session import Reply


class HandBackend:
    """A listening socket the test accepts from and writes to itself."""

    def __init__(self) -> None:
        self.server = socket.socket()
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(4)
        self.server.settimeout(2.0)
        self.address = self.server.getsockname()

    def accept(self) -> socket.socket:
        conn, _ = self.server.accept()
        conn.settimeout(0.3)
        return conn

    def close(self) -> None:
        self.server.close()


def received(conn: socket.socket) -> bytes:
    """What has arrived on `conn` within its timeout."""
    out = b""
    try:
        while chunk := conn.recv(4096):
            out += chunk
    except TimeoutError:
        pass
    return out


@pytest.fixture
def backend() -> Iterator[HandBackend]:
    b = HandBackend()
    yield b
    b.close()


def run(link: McpLink, clock: VirtualClock, seconds: float, step: float = 0.01) -> None:
    for _ in range(round(seconds / step)):
        clock.advance(step)
        link.tick(clock.now(), step)


def connected_link(backend: HandBackend, clock: VirtualClock) -> tuple[McpLink, socket.socket]:
    link = McpLink(backend.address, clock=clock, heartbeat_s=None, backoff_min=0.1)
    link.start()
    conn = backend.accept()
    run(link, clock, 0.05)
    assert link.state == CONNECTED
    return link, conn


def test_a_callback_that_sends_during_a_close_sends_nothing_on_the_next_connection(
        backend: HandBackend) -> None:
    clock = VirtualClock()
    link, first = connected_link(backend, clock)
    seen: list[tuple[str, bool, str | None]] = []

    def on_lost_reply(reply: Reply[Any]) -> None:
        sent = link.send("robot:robot.stop=()", lambda r: seen.append(("stop", True, r.error)))
        seen.append(("get", sent, reply.error))

    assert link.send("demo:demo.get=()", on_lost_reply)
    assert received(first) == b"demo:demo.get=()\n"
    first.close()  # the backend goes away with the request unanswered
    run(link, clock, 0.05)
    assert link.state == DISCONNECTED
    assert seen == [("get", False, seen[0][2])] and "connection lost" in str(seen[0][2])
    run(link, clock, 0.3)
    second = backend.accept()
    run(link, clock, 0.05)
    assert link.state == CONNECTED and link.in_flight == 0
    assert received(second) == b""  # before: b"robot:robot.stop=()\n", sent unasked
    got: list[Reply[Any]] = []
    assert link.send("robot:robot.modules=()", got.append)
    assert received(second) == b"robot:robot.modules=()\n"
    second.sendall(b"robot:robot.modules=(demo)\n")
    run(link, clock, 0.05)
    assert [(r.request, r.line) for r in got] == [(b"robot:robot.modules=()",
                                                   b"robot:robot.modules=(demo)")]
    link.stop()
    second.close()


def test_a_callback_that_sends_while_the_link_is_stopped_is_refused(
        backend: HandBackend) -> None:
    clock = VirtualClock()
    link, conn = connected_link(backend, clock)
    states: list[tuple[str, bool]] = []
    link.send("demo:demo.get=()", lambda r: states.append((link.state, link.send("x:y.z=()"))))
    link.stop()
    assert states == [(STOPPED, False)]
    conn.close()


def test_robot_link_on_done_says_failure_as_failure(backend: HandBackend) -> None:
    clock = VirtualClock()
    link, conn = connected_link(backend, clock)
    robot = RobotLink(link)
    done: list[bool] = []
    assert robot.send("robot:control.acquire=(autonomy)", on_done=done.append)
    assert robot.send("base:base.drive=(10,0)", on_done=done.append)
    assert robot.send("robot:control.acquire=(autonomy)", on_done=done.append)
    assert received(conn).count(b"\n") == 3
    conn.sendall(b"robot:control.owner=(autonomy)\nbase:error=(not_owner,x)\n")
    run(link, clock, 0.05)
    conn.close()  # the third is never answered
    run(link, clock, 0.05)
    assert done == [True, False, False]  # before: [None, None, None], failure or not
    link.stop()
