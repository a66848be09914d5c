"""AsyncMcpClient against small asyncio servers scripted in the test."""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import Awaitable, Callable

import pytest

from ramp.mcp.aio import AsyncMcpClient
from ramp.mcp.messages import Response

Handler = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]


async def serve(handler: Handler) -> tuple[asyncio.Server, int]:
    """A server running `handler` on each connection, and closing the connection after it."""

    async def wrapped(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            await handler(reader, writer)
        finally:
            writer.close()
            with contextlib.suppress(OSError):
                await writer.wait_closed()

    server = await asyncio.start_server(wrapped, "127.0.0.1", 0)
    return server, server.sockets[0].getsockname()[1]


def run(coro: Awaitable[None]) -> None:
    asyncio.run(asyncio.wait_for(coro, 10))  # type: ignore[arg-type]


def echo_values(received: list[bytes]) -> Handler:
    """Answers `x:y.get=(N)` with `x:y.v=(N)`, anything else with a bare line."""

    async def handler(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while line := await reader.readline():
            msg = line.rstrip(b"\n")
            received.append(msg)
            if msg.startswith(b"x:y.get=("):
                writer.write(b"x:y.v=(" + msg[9:-1] + b")\n")
            else:
                writer.write(b"\n")
        writer.close()

    return handler


def test_pipelined_requests_get_their_own_answers() -> None:
    async def main() -> None:
        received: list[bytes] = []
        server, port = await serve(echo_values(received))
        async with server:
            client = await AsyncMcpClient.connect("127.0.0.1", port)
            futures = [client.submit(f"x:y.get=({i})") for i in range(20)]
            replies = await asyncio.gather(*futures)
            assert [r.responses() for r in replies] == [
                [Response("x", "y", "v", (i,))] for i in range(20)]
            assert all(r.rtt is not None and r.rtt >= 0 for r in replies)
            assert await client.request("x:y.get=(7)") == [Response("x", "y", "v", (7,))]
            await client.heartbeat()
            assert received[-1] == b""
            sock = client._writer.get_extra_info("socket")
            assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) != 0
            await client.close()
            await client.close()
            assert client.closed

    run(main())


def test_a_timed_out_request_keeps_the_pairing() -> None:
    async def main() -> None:
        gate = asyncio.Event()

        async def slow(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            await reader.readline()
            await gate.wait()
            writer.write(b"x:y.v=(1)\n")
            await reader.readline()
            writer.write(b"x:y.v=(2)\n")
            await reader.read()

        server, port = await serve(slow)
        async with server:
            client = await AsyncMcpClient.connect("127.0.0.1", port)
            with pytest.raises(TimeoutError):
                await client.request("x:y.get=(1)", timeout=0.05)
            assert client.in_flight == 1 and client.oldest_sent_at() is not None
            gate.set()
            assert await client.request("x:y.get=(2)", timeout=5) == [
                Response("x", "y", "v", (2,))]
            await client.close()

    run(main())


def test_a_busy_greeting_is_kept_and_named_when_the_server_closes() -> None:
    async def main() -> None:
        async def busy(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            writer.write(b"robot:mcp.error=(busy,too many clients)\n")
            await writer.drain()
            await asyncio.sleep(0.05)
            writer.close()

        server, port = await serve(busy)
        async with server:
            client = await AsyncMcpClient.connect("127.0.0.1", port)
            await client.wait_closed()
            # The greeting arrived before anything was asked: kept, and named in the reason.
            assert client.closed and "busy" in client.close_reason
            assert client.unsolicited[0].responses()[0].values[0] == "busy"
            with pytest.raises(ConnectionError, match="closed"):
                client.submit("x:y.get=(2)")
            await client.close()

    run(main())


def test_pending_requests_fail_with_connection_error_when_the_peer_vanishes() -> None:
    async def main() -> None:
        async def mute(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            await reader.readline()
            writer.close()

        server, port = await serve(mute)
        async with server:
            client = await AsyncMcpClient.connect("127.0.0.1", port)
            with pytest.raises(ConnectionError, match="closed the connection"):
                await client.request("x:y.get=(1)", timeout=5)
            await client.close()

    run(main())


def test_connect_refused_is_a_connection_error() -> None:
    probe = socket.create_server(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()

    async def main() -> None:
        with pytest.raises(ConnectionError, match="cannot connect"):
            await AsyncMcpClient.connect("127.0.0.1", port, timeout=1.0)

    run(main())
