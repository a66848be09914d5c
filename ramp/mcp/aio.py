"""An asyncio MCP client on the sans-IO session, for clients that live in an event loop.

The teleop console serves a web page and talks to the robot from one asyncio loop, so it
cannot block on a socket the way `McpClient` does. One reader task feeds received bytes to
`McpSession`, which hands back each reply with the future it was sent with as its tag.
Requests may be pipelined: `submit` writes at once and returns a future; answers arrive in
order. A timed-out request stays paired (its late line is dropped, not given to the next
request), so a caller may keep the connection or drop it as it sees fit.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import ssl
from collections import deque
from typing import Any

from ramp.mcp.messages import Response
from ramp.mcp.session import MAX_RESPONSE_LINE, McpSession, Message, Reply

#: Unsolicited lines kept for a post-mortem (the server's `busy` greeting, say).
_KEEP_UNSOLICITED = 8


class AsyncMcpClient:
    """One TCP connection to a RAMP supervisor, used from an asyncio loop."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                 host: str, port: int) -> None:
        self.host, self.port = host, port
        self._reader, self._writer = reader, writer
        self._session: McpSession[asyncio.Future[Reply[Any]]] = McpSession(MAX_RESPONSE_LINE)
        self._loop = asyncio.get_running_loop()
        self.unsolicited: deque[Reply[Any]] = deque(maxlen=_KEEP_UNSOLICITED)
        self.close_reason = ""
        #: Bytes written and read on this connection (an operator link's bandwidth).
        self.bytes_out = 0
        self.bytes_in = 0
        self._closed = asyncio.Event()
        self._task = asyncio.create_task(self._read_loop(), name=f"mcp-read {host}:{port}")

    @classmethod
    async def connect(cls, host: str, port: int, timeout: float = 2.0,
                      ssl_context: ssl.SSLContext | None = None) -> AsyncMcpClient:
        """Open a connection (inside mutual TLS with `ssl_context`); ConnectionError
        (refused, unreachable, timed out, a handshake refused) otherwise."""
        try:
            reader, writer = await asyncio.wait_for(
                asyncio.open_connection(host, port, ssl=ssl_context,
                                        server_hostname=host if ssl_context else None),
                timeout)
        except (OSError, TimeoutError) as exc:
            reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
            raise ConnectionError(f"cannot connect to {host}:{port}: {reason}") from exc
        sock = writer.get_extra_info("socket")
        if sock is not None:
            # One request, one answer: Nagle would hold a message behind an unacked one.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return cls(reader, writer, host, port)

    def __repr__(self) -> str:
        state = "closed" if self.closed else f"open, {self.in_flight} in flight"
        return f"AsyncMcpClient({self.host}:{self.port}, {state})"

    @property
    def closed(self) -> bool:
        return self._closed.is_set()

    @property
    def in_flight(self) -> int:
        return self._session.in_flight

    def oldest_sent_at(self) -> float | None:
        """Loop time at which the oldest unanswered message was sent."""
        return self._session.oldest_sent_at()

    def submit(self, message: Message) -> asyncio.Future[Reply[Any]]:
        """Write one message now; the future resolves with its reply, or ConnectionError."""
        if self.closed:
            raise ConnectionError(f"connection to {self.host}:{self.port} is closed"
                                  + (f": {self.close_reason}" if self.close_reason else ""))
        future: asyncio.Future[Reply[Any]] = self._loop.create_future()
        data = self._session.send(message, future, self._loop.time())
        self.bytes_out += len(data)
        try:
            self._writer.write(data)
        except (OSError, RuntimeError) as exc:
            self._finish(f"sending failed: {exc}")
        return future

    async def exchange(self, message: Message, timeout: float | None = None) -> Reply[Any]:
        """Send one message and wait for its reply (with its round-trip time)."""
        future = self.submit(message)
        try:
            return await asyncio.wait_for(future, timeout)
        except TimeoutError:
            raise TimeoutError(f"no response from {self.host}:{self.port} within "
                               f"{timeout} s") from None

    async def request(self, message: Message, timeout: float | None = None) -> list[Response]:
        """Send one message and return its responses (ProtocolError if they are not MCP)."""
        return (await self.exchange(message, timeout)).responses()

    async def heartbeat(self, timeout: float | None = None) -> None:
        """A bare `\\n`: feeds the watchdog when this connection is the one driving."""
        await self.exchange(b"", timeout)

    async def wait_closed(self) -> None:
        await self._closed.wait()

    async def close(self) -> None:
        """Close the connection and fail what is still in flight; safe to call twice."""
        self._finish("closed by this client")
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task
        with contextlib.suppress(OSError, RuntimeError):
            await self._writer.wait_closed()

    # -- internals ------------------------------------------------------------------------------
    async def _read_loop(self) -> None:
        reason = f"{self.host}:{self.port} closed the connection"
        try:
            while True:
                data = await self._reader.read(65536)
                if not data:
                    break
                self.bytes_in += len(data)
                for reply in self._session.feed(data, self._loop.time()):
                    future = reply.tag
                    if future is None:
                        self.unsolicited.append(reply)
                    elif not future.done():
                        future.set_result(reply)
        except OSError as exc:
            reason = f"connection to {self.host}:{self.port} failed: {exc}"
        finally:
            self._finish(reason)

    def _finish(self, reason: str) -> None:
        if self._closed.is_set():
            return
        last = self.unsolicited[-1].line.decode("ascii", "replace") if self.unsolicited else ""
        self.close_reason = f"{reason} ({last})" if last else reason
        self._closed.set()
        with contextlib.suppress(OSError, RuntimeError):
            self._writer.close()
        for pending in self._session.reset():
            future = pending.tag
            if future is not None and not future.done():
                future.set_exception(ConnectionError(self.close_reason))
