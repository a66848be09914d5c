"""The autonomy's connection to the backend: MCP over TCP, driven from the scheduler's loop.

The blocking `ramp.mcp.client.McpClient` waits for each answer, which a tick cannot do, and
cannot run in the thread that also runs the supervisor (a simulation on one scheduler would
wait for itself). This client never blocks: the connect is non-blocking, bytes are read when
the socket is readable (`on_readable`, registered with the loop's `add_reader`, or polled from
`tick`) and written without waiting, and every answer comes back to a callback. Request and
response pairing is `ramp.mcp.session.McpSession`'s (SPEC 2: one response line per message,
in order), the same core the shell and the console use.

- `send(message, on_reply)` writes one message (text, a `Request` or several) and returns at
  once; `on_reply(reply)` is called from the loop with the `Reply` when its line arrives
  (`reply.responses()` parses it). Nothing is queued while disconnected: `send` says False,
  and the caller (the mission) decides what a lost command means.
- A **heartbeat** (a bare line) goes out whenever nothing was sent for `heartbeat_s`, so the
  backend's watchdog stays fed while the autonomy drives (SPEC 2.2: only the feeder's messages
  count) and a dead autonomy stops the robot.
- A backend that does not answer within `reply_timeout`, a closed or refused connection, or a
  `busy` greeting: the link is dropped, every unanswered message's callback gets a reply whose
  `error` says why, and it reconnects after a back-off that doubles up to `backoff_max`.
  `on_connect(link)` runs after every connect: that is where the mission (re)acquires control.
- Those callbacks run once the link already reads DISCONNECTED (or STOPPED), so a callback
  that sends is refused (False), and every connection starts from a clean slate: nothing
  pending, nothing buffered. (Before, a callback that sent during a close wrote into a buffer
  the next connection then sent, and its replies were paired with the wrong requests.)

The socket, the non-blocking connect and the back-off are `ramp.common.tcpclient.TcpClient`'s,
shared with the Hokuyo driver.

Time comes only from the injected clock.
"""

from __future__ import annotations

import contextlib
import logging
import math
import ssl
from collections.abc import Callable, Iterable

from ramp.clock import Clock
from ramp.common import tcpclient
from ramp.common.hostport import parse_hostport
from ramp.common.tcpclient import IoLoop, TcpClient, check_seconds
from ramp.errors import ProtocolError
from ramp.mcp.messages import Request
from ramp.mcp.session import McpSession, Reply

log = logging.getLogger("ramp.autonomy.mcp")

ReplyCallback = Callable[[Reply["ReplyCallback | None"]], None]
Message = str | bytes | Request | Iterable[Request]

STOPPED = "stopped"
CONNECTING = "connecting"
CONNECTED = "connected"
DISCONNECTED = "disconnected"

_STATES = {tcpclient.IDLE: STOPPED, tcpclient.WAITING: DISCONNECTED,
           tcpclient.CONNECTING: CONNECTING, tcpclient.CONNECTED: CONNECTED}
__all__ = ["CONNECTED", "CONNECTING", "DISCONNECTED", "STOPPED", "IoLoop", "McpLink",
           "parse_backend"]


def parse_backend(address: str | tuple[str, int]) -> tuple[str, int]:
    """`HOST:PORT`, `[v6]:PORT` or (host, port) -> (host, port); ValueError says why."""
    if isinstance(address, tuple):
        host, port = address
        if not host or not 0 < int(port) < 65536:
            raise ValueError(f"{address!r}: expected a host and a port 1-65535")
        return str(host), int(port)
    return parse_hostport(address)


class McpLink:
    """One MCP connection to a backend, serviced by `tick(now, dt)` and the loop's reader."""

    def __init__(self, address: str | tuple[str, int], *, clock: Clock,
                 loop: IoLoop | None = None, name: str = "backend",
                 reply_timeout: float = 2.0, heartbeat_s: float | None = 0.25,
                 connect_timeout: float = 2.0, backoff_min: float = 0.5,
                 backoff_max: float = 8.0,
                 on_connect: Callable[[McpLink], None] | None = None,
                 ssl_context: ssl.SSLContext | None = None) -> None:
        """`ssl_context`: the link runs inside mutual TLS (`mcps://`, SPEC 13)."""
        host, port = parse_backend(address)
        check_seconds(name, reply_timeout=reply_timeout, connect_timeout=connect_timeout,
                      backoff_min=backoff_min, backoff_max=backoff_max,
                      heartbeat_s=1.0 if heartbeat_s is None else heartbeat_s)
        self.clock = clock
        self.name = name
        self.reply_timeout = reply_timeout
        self.heartbeat_s = heartbeat_s
        self.on_connect = on_connect
        #: Lines nobody asked for (a `busy` greeting), newest last, for the mission to read.
        self.unsolicited: list[bytes] = []
        self.stats = {"connects": 0, "connect_failures": 0, "disconnects": 0, "sent": 0,
                      "replies": 0, "heartbeats": 0, "timeouts": 0, "lost_requests": 0}
        self.fault = ""
        self.client = TcpClient(host, port, now=clock.now, loop=loop, ssl_context=ssl_context,
                                connect_timeout=connect_timeout, backoff_min=backoff_min,
                                backoff_max=backoff_max, on_connected=self._connected,
                                on_data=self._on_data, on_lost=self._lost,
                                on_eof=self._eof_reason, stats=self.stats)
        self._session: McpSession[ReplyCallback | None] = McpSession()
        self._last_sent = -math.inf
        self._connection = 0  # counts connects and losses: replies of an old one are dropped

    # -- state ------------------------------------------------------------------------------
    @property
    def address(self) -> str:
        return self.client.address

    @property
    def state(self) -> str:
        """STOPPED, CONNECTING, CONNECTED or DISCONNECTED (waiting to retry)."""
        return _STATES[self.client.state]

    @property
    def connected(self) -> bool:
        return self.client.connected

    @property
    def in_flight(self) -> int:
        """Messages sent and not answered yet."""
        return self._session.in_flight

    def fileno(self) -> int:
        return self.client.fileno()

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self) -> None:
        """Begin connecting; returns at once (a host *name* is resolved here, once, which
        can wait on DNS: give the backend's IP address)."""
        self.client.start()

    def tick(self, now: float, dt: float) -> None:
        self.client.tick(now)
        if not self.client.connected:
            return
        oldest = self._session.oldest_sent_at()
        if oldest is not None and now - oldest > self.reply_timeout:
            self.stats["timeouts"] += 1
            self.client.drop(now, f"no reply within {self.reply_timeout:g} s")
            return
        if self.heartbeat_s is not None and now - self._last_sent >= self.heartbeat_s:
            self.stats["heartbeats"] += 1
            self._write(b"", None, now)

    def stop(self) -> None:
        """Close the connection (unanswered callbacks get an error reply); idempotent."""
        if self.state == STOPPED:
            return
        self.client.close()  # STOPPED before any callback runs: a send from one is refused
        self._fail_pending(self.clock.now(), "the link was stopped")

    close = stop

    # -- requests ----------------------------------------------------------------------------
    def send(self, message: Message, on_reply: ReplyCallback | None = None) -> bool:
        """Write one message; False (and nothing sent) while not connected. ValueError for a
        message that is not one MCP message (see `ramp.mcp.session.encode_message`)."""
        if not self.client.connected:
            return False
        self._write(message, on_reply, self.clock.now())
        return self.client.connected

    def _write(self, message: Message, on_reply: ReplyCallback | None, now: float) -> None:
        data = self._session.send(message, on_reply, now)
        self._last_sent = now
        self.stats["sent"] += 1
        self.client.write(data)

    # -- I/O ----------------------------------------------------------------------------------
    def on_readable(self) -> None:
        """Read what has arrived and hand each reply to its callback (never blocks)."""
        self.client.on_readable()

    def _on_data(self, data: bytes, now: float) -> None:
        connection = self._connection
        for reply in self._session.feed(data, now):
            if self._connection != connection:
                return  # a callback closed the link: the rest belongs to a dead connection
            self._deliver(reply)

    def _eof_reason(self, now: float) -> str:
        if self.unsolicited and b"busy" in self.unsolicited[-1]:
            return f"the backend is busy ({self.unsolicited[-1].decode('ascii', 'replace')})"
        return "the backend closed the connection"

    def _deliver(self, reply: Reply[ReplyCallback | None]) -> None:
        if reply.unsolicited:
            self.unsolicited.append(reply.line)
            del self.unsolicited[:-16]
            log.warning("%s: %s says %s", self.name, self.address,
                        reply.line.decode("ascii", "replace"))
            return
        self.stats["replies"] += 1
        callback = reply.tag
        if callback is None:
            if reply.line:
                with contextlib.suppress(ProtocolError):
                    for r in reply.responses():
                        if r.prop == "error":
                            log.warning("%s: %s -> %s", self.name,
                                        (reply.request or b"").decode("ascii", "replace"),
                                        reply.line.decode("ascii", "replace"))
                            break
            return
        try:
            callback(reply)
        except Exception:
            log.exception("%s: reply callback raised; the link goes on", self.name)

    # -- connecting and losing it -------------------------------------------------------------
    def _connected(self, now: float) -> None:
        # A clean slate: nothing of an earlier connection is paired with this one's replies.
        self._connection += 1
        self._fail_pending(now, "a new connection began")
        if self.fault:
            log.info("%s: connected to %s again (was: %s)", self.name, self.address,
                     self.fault)
        else:
            log.info("%s: connected to %s", self.name, self.address)
        self.fault = ""
        self.client.reset_backoff()
        self._last_sent = now
        if self.on_connect is not None:
            try:
                self.on_connect(self)
            except Exception:
                log.exception("%s: on_connect raised", self.name)

    def _lost(self, now: float, reason: str) -> None:
        """The client has closed the socket and reads DISCONNECTED: callbacks run now."""
        self.fault = f"{self.name} at {self.address}: {reason}"
        log.warning("%s; retrying in %.2g s", self.fault, self.client.retry_at - now)
        self._fail_pending(now, f"connection lost: {reason}")

    def _fail_pending(self, now: float, error: str) -> None:
        self._connection += 1
        for pending in self._session.reset():
            self.stats["lost_requests"] += 1
            if pending.tag is not None:
                try:
                    pending.tag(Reply(b"", pending.request, pending.tag, pending.sent_at, now,
                                      error=error))
                except Exception:
                    log.exception("%s: reply callback raised", self.name)
