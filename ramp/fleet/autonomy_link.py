"""The agent's link to the autonomy's command endpoint (ramp/autonomy/command.py): JSON lines
on loopback TCP, non-blocking on the agent's loop (`ramp.common.tcpclient.TcpClient`).

The agent reaches the autonomy only here, never by importing it: a robot without the
autonomy has no endpoint and no link, and its agent still answers everything but orders.
`status` is the newest status line (empty while disconnected); `command(cmd, on_reply,
**args)` sends one command, its answer comes to `on_reply(reply)` in order.
"""

from __future__ import annotations

import json
import logging
from collections import deque
from collections.abc import Callable
from typing import Any

from ramp.clock import Clock
from ramp.common.hostport import format_hostport
from ramp.common.tcpclient import IoLoop, TcpClient

log = logging.getLogger("ramp.fleet.autonomy")

OnReply = Callable[[dict[str, Any]], None]


class AutonomyLink:
    def __init__(self, host: str, port: int, *, clock: Clock, loop: IoLoop | None = None,
                 on_connect: Callable[[], None] | None = None) -> None:
        self.address = format_hostport(host, port)
        self.on_connect = on_connect
        self.client = TcpClient(host, port, now=clock.now, loop=loop, backoff_min=0.5,
                                backoff_max=4.0, on_connected=self._connected,
                                on_data=self._on_data, on_lost=self._lost)
        self._status: dict[str, Any] = {}
        self._buf = bytearray()
        self._pending: deque[OnReply | None] = deque()
        self.fault = "not connected yet"

    @property
    def connected(self) -> bool:
        return self.client.connected

    @property
    def status(self) -> dict[str, Any]:
        return self._status if self.client.connected else {}

    def start(self) -> None:
        self.client.start()

    def close(self) -> None:
        self.client.close()
        self._reset("the link was closed")

    def tick(self, now: float, dt: float) -> None:
        self.client.tick(now)

    def command(self, cmd: str, on_reply: OnReply | None = None, **args: Any) -> bool:
        """Send one command; False (not sent) while disconnected."""
        if not self.client.connected:
            return False
        self._pending.append(on_reply)
        return self.client.write(json.dumps({"cmd": cmd, **args}).encode() + b"\n")

    def _on_data(self, data: bytes, now: float) -> None:
        self._buf += data
        while b"\n" in self._buf:
            raw, _, rest = bytes(self._buf).partition(b"\n")
            self._buf = bytearray(rest)
            try:
                msg = json.loads(raw)
            except ValueError:
                log.warning("autonomy at %s: not a JSON line: %r", self.address, raw[:80])
                continue
            if not isinstance(msg, dict):
                continue
            if "status" in msg and "re" not in msg:
                if isinstance(msg["status"], dict):
                    self._status = msg["status"]
                continue
            if "status" in msg and isinstance(msg["status"], dict):
                self._status = msg["status"]
            callback = self._pending.popleft() if self._pending else None
            if callback is not None:
                try:
                    callback(msg)
                except Exception:
                    log.exception("an autonomy reply callback raised")

    def _connected(self, now: float) -> None:
        self._buf.clear()
        self.client.reset_backoff()
        log.info("connected to the autonomy at %s", self.address)
        self.fault = ""
        self.command("status")
        if self.on_connect is not None:
            self.on_connect()

    def _lost(self, now: float, reason: str) -> None:
        if not self.fault:
            log.warning("autonomy at %s: %s", self.address, reason)
        self.fault = reason
        self._reset(reason)

    def _reset(self, reason: str) -> None:
        self._status = {}
        pending, self._pending = self._pending, deque()
        for callback in pending:
            if callback is not None:
                try:
                    callback({"ok": False, "error": f"no answer: {reason}"})
                except Exception:
                    log.exception("an autonomy reply callback raised")
