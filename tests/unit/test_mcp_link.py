"""The autonomy's tick-driven MCP link: a real supervisor on the same scheduler and virtual
clock, spoken to over real TCP, plus silent, refusing, closing and busy backends."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest

from ramp.autonomy.mcp_link import CONNECTED, DISCONNECTED, McpLink, parse_backend
from ramp.mcp.session import Reply
from tests.harness import DEMO_YAML, Harness

Replies = list[Reply[object]]


LINKS: list[McpLink] = []


@pytest.fixture
def harness() -> Iterator[Harness]:
    h = Harness(DEMO_YAML)
    yield h
    close(h)


def close(h: Harness) -> None:
    while LINKS:
        LINKS.pop().stop()
    h.close()


def attach(h: Harness, address: tuple[str, int] | None = None, **kw: object) -> McpLink:
    """A link on the supervisor's own scheduler, as the autonomy runs in a simulation."""
    link = McpLink(address or h.sup.server.address, clock=h.clock, loop=h.sup.scheduler,
                   **kw)  # type: ignore[arg-type]
    h.sup.scheduler.add_task("autonomy.mcp", h.sup.scheduler.rate_hz, link.tick)
    link.start()
    LINKS.append(link)
    return link


def test_replies_come_back_to_their_callbacks_in_order(harness: Harness) -> None:
    link = attach(harness)
    harness.advance(0.05)
    assert link.state == CONNECTED
    got: Replies = []
    assert link.send("robot:robot.modules=()", got.append)
    assert link.send("demo:motor.vel=(20)demo:motor.vel=(300)", got.append)
    assert link.send("demo:demo.get=()", got.append)
    assert link.in_flight == 3
    harness.advance(0.05)
    assert [r.request for r in got] == [b"robot:robot.modules=()",
                                        b"demo:motor.vel=(20)demo:motor.vel=(300)",
                                        b"demo:demo.get=()"]
    assert got[0].line == b"robot:robot.modules=(demo,arm)"
    assert got[1].responses()[0].prop == "error"  # 300 is out of range; 20 was taken
    assert got[2].line == b"demo:motor.vel=(20)demo:lamp.on=(0)"
    assert got[0].rtt is not None and got[0].rtt <= 0.02  # answered within a tick or two
    assert link.stats["replies"] >= 3


def test_heartbeats_keep_the_watchdog_fed_while_the_autonomy_drives(harness: Harness) -> None:
    link = attach(harness, heartbeat_s=0.2)
    harness.advance(0.05)
    link.send("robot:control.acquire=(autonomy)")
    link.send("demo:motor.vel=(40)")
    harness.advance(3.0)  # six watchdog timeouts with nothing but heartbeats
    assert harness.world.motors["demo.motor"] == pytest.approx(0.4)
    assert link.stats["heartbeats"] >= 10
    link.heartbeat_s = None  # the autonomy hangs: the backend must stop the motor
    harness.advance(1.0)
    assert harness.world.motors["demo.motor"] == 0.0


def test_a_backend_that_never_answers_is_dropped_and_the_caller_told(harness: Harness) -> None:
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(1)
    try:
        link = attach(harness, silent.getsockname(), reply_timeout=0.5, heartbeat_s=None)
        harness.advance(0.05)
        assert link.state == CONNECTED  # the kernel accepted; nobody reads
        got: Replies = []
        link.send("robot:robot.modules=()", got.append)
        harness.advance(0.7)
        assert link.state == DISCONNECTED and "no reply within 0.5 s" in link.fault
        assert len(got) == 1 and got[0].error is not None and "connection lost" in got[0].error
        assert not link.send("robot:robot.stop=()")  # nothing is queued while down
        assert link.stats["timeouts"] == 1
    finally:
        link.stop()
        for conn in accepted(silent):
            conn.close()
        silent.close()


def test_a_refused_connect_backs_off_and_connects_once_the_backend_is_up(
        harness: Harness) -> None:
    spare = socket.socket()
    spare.bind(("127.0.0.1", 0))
    port = spare.getsockname()[1]
    spare.close()  # nothing listens there now
    connects: list[float] = []
    link = attach(harness, ("127.0.0.1", port), backoff_min=0.5,
                  on_connect=lambda ln: connects.append(harness.clock.now()))
    harness.advance(2.0)
    assert link.state == DISCONNECTED and "ECONNREFUSED" in link.fault
    assert 2 <= link.stats["connect_failures"] <= 3  # at 0, 0.5, 1.5 s: the back-off doubles
    link.client.set_address(*harness.sup.server.address)  # resolved again at the next try
    harness.advance(3.0)
    assert link.state == CONNECTED and len(connects) == 1


def test_a_closed_connection_fails_what_was_pending_and_reconnects(harness: Harness) -> None:
    acquired: Replies = []
    link = attach(harness, backoff_min=0.2,
                  on_connect=lambda ln: ln.send("robot:control.acquire=(autonomy)",
                                                acquired.append))
    harness.advance(0.1)
    assert [r.line for r in acquired] == [b""]
    sock = socket.fromfd(link.fileno(), socket.AF_INET, socket.SOCK_STREAM)
    sock.shutdown(socket.SHUT_RDWR)  # the cable is pulled
    sock.close()
    harness.advance(1.0)
    assert link.stats["disconnects"] == 1 and link.state == CONNECTED
    assert len(acquired) == 2  # on_connect ran again: control is taken back


def test_a_busy_backend_is_reported_as_busy() -> None:
    h = Harness(DEMO_YAML.replace("max_clients: 4", "max_clients: 1"))
    try:
        first = attach(h)
        h.advance(0.05)
        second = attach(h, backoff_min=5.0)
        h.advance(0.1)
        assert first.state == CONNECTED
        assert second.state == DISCONNECTED and "busy" in second.fault
    finally:
        close(h)


def accepted(server: socket.socket) -> list[socket.socket]:
    server.setblocking(False)
    out = []
    while True:
        try:
            out.append(server.accept()[0])
        except BlockingIOError:
            return out


def test_addresses_are_checked() -> None:
    assert parse_backend("192.168.0.20:5577") == ("192.168.0.20", 5577)
    assert parse_backend("[::1]:5577") == ("::1", 5577)
    for bad in ("robot", "robot:x", "[::1]5577", ":5577"):
        with pytest.raises(ValueError):
            parse_backend(bad)
