"""`ramp.common.tcpclient.TcpClient`, the socket under the autonomy's MCP link and the
Hokuyo driver: its back-off, and what the owner sees from inside `on_lost`."""

from __future__ import annotations

import socket

from ramp.clock import VirtualClock
from ramp.common.tcpclient import CONNECTED, IDLE, WAITING, TcpClient


def test_backoff_doubles_to_its_cap_and_a_reset_starts_it_again() -> None:
    spare = socket.socket()
    spare.bind(("127.0.0.1", 0))
    port = spare.getsockname()[1]
    spare.close()  # nothing listens: every attempt is refused
    clock = VirtualClock()
    lost: list[tuple[float, str]] = []
    client = TcpClient("127.0.0.1", port, now=clock.now, backoff_min=0.5, backoff_max=2.0,
                       on_lost=lambda now, why: lost.append((now, why)))
    client.start()
    for _ in range(800):
        clock.advance(0.01)
        client.tick(clock.now())
    gaps = [b[0] - a[0] for a, b in zip(lost, lost[1:], strict=False)]
    assert len(gaps) == 5
    assert all(abs(g - want) <= 0.03 for g, want in zip(gaps, [0.5, 1, 2, 2, 2], strict=True))
    assert all("ECONNREFUSED" in why for _, why in lost)
    assert client.stats["connect_failures"] == 6 and client.stats["disconnects"] == 0
    client.reset_backoff()
    assert client.backoff == 0.5
    client.close()
    assert client.state == IDLE


def test_inside_on_lost_the_client_is_no_longer_connected_and_refuses_writes() -> None:
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    clock = VirtualClock()
    seen: list[tuple[str, bool, int]] = []
    client: TcpClient

    def on_lost(now: float, why: str) -> None:
        seen.append((client.state, client.write(b"late\n"), client.pending_out))

    client = TcpClient(*server.getsockname(), now=clock.now, on_lost=on_lost)
    client.start()
    conn, _ = server.accept()
    client.tick(clock.now())
    assert client.state == CONNECTED and client.write(b"hello\n")
    conn.settimeout(1.0)
    assert conn.recv(100) == b"hello\n"
    client.drop(clock.now(), "test")
    assert seen == [(WAITING, False, 0)]
    assert client.stats == {"connects": 1, "connect_failures": 0, "disconnects": 1}
    client.close()
    conn.close()
    server.close()
