"""The agent's MCP connection to its robot's backend, serviced from the agent's loop.

Non-blocking like the autonomy's link (the socket, the connect and the back-off are
`ramp.common.tcpclient.TcpClient`'s; the request/response pairing is `ramp.mcp.session`'s),
and kept apart from it so the fleet never imports the autonomy: either can be removed.

`send(message, on_reply)` writes one message and calls `on_reply(responses, error)` when its
line arrives (`error` is "" or why there will be no answer: the link was lost). A heartbeat
goes out whenever nothing was sent for `heartbeat_s`, so the agent's own commands feed the
backend's watchdog as any client's do (SPEC 2.2), and an agent that dies is a silent client.
"""

from __future__ import annotations

import logging
import math
import ssl
from collections.abc import Callable

from ramp.clock import Clock
from ramp.common.tcpclient import IoLoop, TcpClient
from ramp.errors import ProtocolError
from ramp.mcp.messages import Response
from ramp.mcp.session import McpSession, Message, Reply

log = logging.getLogger("ramp.fleet.mcp")

OnReply = Callable[[list[Response], str], None]


class FleetMcpLink:
    """One MCP connection; `tick(now, dt)` from a scheduler task."""

    def __init__(self, host: str, port: int, *, clock: Clock, loop: IoLoop | None = None,
                 reply_timeout: float = 2.0, heartbeat_s: float = 0.25,
                 on_connect: Callable[[], None] | None = None,
                 on_lost: Callable[[str], None] | None = None,
                 ssl_context: ssl.SSLContext | None = None) -> None:
        self.clock = clock
        self.reply_timeout = reply_timeout
        self.heartbeat_s = heartbeat_s
        self.on_connect = on_connect
        self.on_lost_cb = on_lost
        self.fault = "not connected yet"
        self.client = TcpClient(host, port, now=clock.now, loop=loop, backoff_min=0.25,
                                ssl_context=ssl_context,
                                backoff_max=2.0, on_connected=self._connected,
                                on_data=self._on_data, on_lost=self._lost)
        self._session: McpSession[OnReply | None] = McpSession()
        self._last_sent = -math.inf
        self._generation = 0

    @property
    def connected(self) -> bool:
        return self.client.connected

    @property
    def address(self) -> str:
        return self.client.address

    def start(self) -> None:
        self.client.start()

    def close(self) -> None:
        self.client.close()
        self._fail_pending("the link was closed")

    def tick(self, now: float, dt: float = 0.0) -> None:
        self.client.tick(now)
        if not self.client.connected:
            return
        oldest = self._session.oldest_sent_at()
        if oldest is not None and now - oldest > self.reply_timeout:
            self.client.drop(now, f"no reply within {self.reply_timeout:g} s")
            return
        if now - self._last_sent >= self.heartbeat_s:
            self._write(b"", None, now)

    def send(self, message: Message, on_reply: OnReply | None = None) -> bool:
        """Write one message; False (nothing sent) while not connected."""
        if not self.client.connected:
            return False
        self._write(message, on_reply, self.clock.now())
        return self.client.connected

    def _write(self, message: Message, on_reply: OnReply | None, now: float) -> None:
        data = self._session.send(message, on_reply, now)
        self._last_sent = now
        self.client.write(data)

    def _on_data(self, data: bytes, now: float) -> None:
        generation = self._generation
        for reply in self._session.feed(data, now):
            if generation != self._generation:
                return
            self._deliver(reply)

    def _deliver(self, reply: Reply[OnReply | None]) -> None:
        if reply.unsolicited:
            log.warning("backend %s says %s", self.address,
                        reply.line.decode("ascii", "replace"))
            return
        if reply.tag is None:
            return
        try:
            responses = reply.responses()
        except ProtocolError as exc:
            reply.tag([], f"unreadable answer: {exc}")
            return
        try:
            reply.tag(responses, "")
        except Exception:
            log.exception("a reply callback raised; the agent goes on")

    def _connected(self, now: float) -> None:
        self._fail_pending("a new connection began")
        self.client.reset_backoff()
        self._last_sent = now
        if self.fault:
            log.info("connected to the backend at %s", self.address)
        self.fault = ""
        if self.on_connect is not None:
            self.on_connect()

    def _lost(self, now: float, reason: str) -> None:
        if not self.fault:
            log.warning("backend at %s: %s", self.address, reason)
        self.fault = reason
        self._fail_pending(f"connection lost: {reason}")
        if self.on_lost_cb is not None:
            self.on_lost_cb(reason)

    def _fail_pending(self, error: str) -> None:
        self._generation += 1
        for pending in self._session.reset():
            if pending.tag is not None:
                try:
                    pending.tag([], error)
                except Exception:
                    log.exception("a reply callback raised")
