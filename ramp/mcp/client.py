"""A small blocking MCP client for the shell, benchmarks and tests.

It blocks by design: it runs in a client process, never in the supervisor's tick. The
pairing of messages and lines is `ramp.mcp.session.McpSession`'s, which the asyncio client
shares; this file only moves bytes over a socket and waits.
"""

from __future__ import annotations

import socket
import ssl
import time
from collections import deque
from collections.abc import Iterable
from types import TracebackType

from ramp.common.hostport import parse_hostport
from ramp.errors import ProtocolError
from ramp.mcp.messages import Request, Response
from ramp.mcp.protocol import parse_response_line
from ramp.mcp.session import MAX_RESPONSE_LINE, McpSession, Reply

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 5577
__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "MAX_RESPONSE_LINE", "McpClient", "errors",
           "parse_address"]


def parse_address(text: str | None, default_port: int = DEFAULT_PORT) -> tuple[str, int]:
    """`host:port`, `port`, `host`, `[v6]:port`, a bare IPv6 address or None -> (host, port)
    (`ramp.common.hostport`, defaulting to this machine and the MCP port); ValueError."""
    return parse_hostport(text or "", default_host=DEFAULT_HOST, default_port=default_port,
                          example=f"robot.local:{DEFAULT_PORT}")


def errors(responses: Iterable[Response]) -> list[Response]:
    """The error responses among `responses`."""
    return [r for r in responses if r.prop == "error"]


class McpClient:
    """One TCP connection to a RAMP supervisor."""

    errors = staticmethod(errors)

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 timeout: float = 2.0, ssl_context: ssl.SSLContext | None = None) -> None:
        """`ssl_context`: MCP inside mutual TLS (`mcps://`, `ramp.common.endpoint`)."""
        self.host, self.port, self.timeout = host, port, timeout
        self._session: McpSession[None] = McpSession(MAX_RESPONSE_LINE)
        self._lines: deque[Reply[None]] = deque()
        sock = socket.create_connection((host, port), timeout)
        if ssl_context is not None:
            try:
                sock = ssl_context.wrap_socket(sock, server_hostname=host)
            except BaseException:
                sock.close()
                raise
        self._sock: socket.socket | None = sock
        # Requests are small and latency matters more than packet count (one request, one
        # answer): without this Nagle holds a message back behind an unacknowledged one.
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def __enter__(self) -> McpClient:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "open" if self._sock is not None else "closed"
        return f"McpClient({self.host}:{self.port}, {state})"

    @property
    def closed(self) -> bool:
        return self._sock is None

    def fileno(self) -> int:
        """The socket's descriptor, for select() in a watch loop."""
        return self._connected().fileno()

    def has_line(self) -> bool:
        """A complete response line is already buffered (recv will not block)."""
        return bool(self._lines)

    def send(self, message: str | bytes | Request | Iterable[Request] = "") -> None:
        """Write one message; the `\\n` is added here, so the text must not contain one."""
        sock = self._connected()
        data = self._session.send(message)
        try:
            sock.sendall(data)
        except OSError as exc:
            self.close()
            raise ConnectionError(f"sending to {self.host}:{self.port} failed: {exc}") from exc

    def recv(self) -> list[Response]:
        """The next response line, parsed; TimeoutError after `timeout` s without one."""
        return parse_response_line(self.recv_line())

    def recv_line(self) -> bytes:
        """The next raw response line (no `\\n`), for callers that print it as it came."""
        sock = self._connected()
        deadline = time.monotonic() + self.timeout
        while not self._lines:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no response from {self.host}:{self.port} "
                                   f"within {self.timeout} s")
            sock.settimeout(remaining)
            try:
                data = sock.recv(65536)
            except TimeoutError:
                raise TimeoutError(f"no response from {self.host}:{self.port} "
                                   f"within {self.timeout} s") from None
            except OSError as exc:
                self.close()
                raise ConnectionError(f"connection to {self.host}:{self.port} failed: "
                                      f"{exc}") from exc
            if not data:
                self.close()
                raise ConnectionError(f"{self.host}:{self.port} closed the connection")
            self._lines.extend(self._session.feed(data))
        reply = self._lines.popleft()
        if reply.error is not None:
            raise ProtocolError(reply.error)
        return reply.line

    def request(self, message: str | bytes | Request | Iterable[Request]) -> list[Response]:
        """Send one message and return its responses."""
        self.send(message)
        return self.recv()

    def heartbeat(self) -> list[Response]:
        """Send a bare `\\n` (keeps the watchdog fed when this client drives); [] expected."""
        return self.request(b"")

    def close(self) -> None:
        """Close the connection; safe to call more than once."""
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()
            self._session.reset()

    def _connected(self) -> socket.socket:
        if self._sock is None:
            raise ConnectionError(f"connection to {self.host}:{self.port} is closed")
        return self._sock
