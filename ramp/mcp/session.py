"""The client side of MCP, sans-IO: pairs each request message with its one response line.

SPEC 2 promises that every request message gets exactly one response line, in order. So a
client needs no ids: a first-in first-out queue of what it sent is enough to know which
request a line answers. `McpSession` is that queue plus the line framing. It never touches a
socket or reads a clock: a transport hands it the bytes it received (and, if it wants round
trip times, the time), and writes the bytes `send` returns. Every MCP client in RAMP stands
on it: the blocking `McpClient` (shell, tests, benchmarks), the asyncio client of the teleop
console (`ramp.mcp.aio`), and a tick-driven client that polls a socket inside a scheduler task.

A tag of the caller's choosing rides with each request (a future, a callback, a step name)
and comes back on its `Reply`, so the transport needs no table of its own.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Generic, TypeVar

from ramp.errors import ProtocolError
from ramp.mcp.messages import Request, Response
from ramp.mcp.protocol import LineSplitter, TooLong, format_requests, parse_response_line

#: A describe of a large robot runs to a few kilobytes; a line anywhere near this is not MCP.
MAX_RESPONSE_LINE = 1 << 20

#: What a client may hand over as one message: its text (with or without the final `\\n`),
#: one request, or several requests sent together.
Message = str | bytes | Request | Iterable[Request]

T = TypeVar("T")


def encode_message(message: Message) -> bytes:
    """One request message as bytes to write, ending in exactly one `\\n`.

    Text must hold a single message: an inner line break would make two messages and two
    answers, and break the pairing, so it is refused (ValueError). `""` is a heartbeat.
    """
    if isinstance(message, Request):
        return format_requests([message])
    if isinstance(message, str | bytes):
        raw = message.encode("ascii") if isinstance(message, str) else bytes(message)
        if raw.endswith(b"\n"):
            raw = raw[:-1]
        if b"\n" in raw:
            raise ValueError("one message per send: the text contains a line break")
        return raw + b"\n"
    return format_requests(message)


@dataclass(frozen=True, slots=True)
class Reply(Generic[T]):
    """One response line and the request message it answers."""

    #: The response line without its `\\n` (and `\\r`); empty when every action succeeded.
    line: bytes
    #: The message it answers, without `\\n`; None for a line nobody asked for (the server's
    #: `busy` greeting, or a line after `reset`).
    request: bytes | None = None
    tag: T | None = None
    sent_at: float | None = None
    received_at: float | None = None
    #: Why the line could not be kept (it was too long); `responses()` raises it.
    error: str | None = None

    @property
    def unsolicited(self) -> bool:
        return self.request is None

    @property
    def rtt(self) -> float | None:
        """Seconds from send to answer, when both times were given."""
        if self.sent_at is None or self.received_at is None:
            return None
        return self.received_at - self.sent_at

    def responses(self) -> list[Response]:
        """The line's responses, typed; ProtocolError if it is not an MCP response line."""
        if self.error is not None:
            raise ProtocolError(self.error)
        return parse_response_line(self.line)


@dataclass(frozen=True, slots=True)
class Pending(Generic[T]):
    """A request message written and not yet answered."""

    request: bytes
    tag: T | None
    sent_at: float | None


class McpSession(Generic[T]):
    """Request/response pairing for one connection; bytes in, bytes and replies out."""

    def __init__(self, max_line: int = MAX_RESPONSE_LINE) -> None:
        self.max_line = max_line
        self._splitter = LineSplitter(max_line)
        self._pending: deque[Pending[T]] = deque()

    @property
    def in_flight(self) -> int:
        """Messages sent and not answered yet."""
        return len(self._pending)

    def oldest_sent_at(self) -> float | None:
        """When the oldest unanswered message was sent, to time out a silent peer."""
        return self._pending[0].sent_at if self._pending else None

    def send(self, message: Message, tag: T | None = None, now: float | None = None) -> bytes:
        """Record one message as sent and return its bytes; the caller must write all of them.

        ValueError (from `encode_message`) leaves the session unchanged.
        """
        data = encode_message(message)
        self._pending.append(Pending(data[:-1], tag, now))
        return data

    def feed(self, data: bytes, now: float | None = None) -> list[Reply[T]]:
        """Received bytes in; every reply they complete out, in order.

        A line longer than `max_line` still answers its request (pairing holds), as a reply
        whose `error` says so.
        """
        out: list[Reply[T]] = []
        for item in self._splitter.feed(data):
            first = self._pending.popleft() if self._pending else None
            request, tag, sent_at = ((first.request, first.tag, first.sent_at)
                                     if first is not None else (None, None, None))
            if isinstance(item, TooLong):
                error = f"response line longer than {self.max_line} bytes"
                out.append(Reply(b"", request, tag, sent_at, now, error))
            else:
                out.append(Reply(item, request, tag, sent_at, now))
        return out

    def reset(self) -> list[Pending[T]]:
        """Forget the connection (closed, or about to be replaced); returns what went unanswered.

        A partial line is dropped too, so a new connection starts clean.
        """
        lost = list(self._pending)
        self._pending.clear()
        self._splitter.reset()
        return lost
