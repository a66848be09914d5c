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

Time comes only from the injected clock.
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import logging
import math
import os
import select
import socket
from collections.abc import Callable, Iterable
from typing import Protocol

from ramp.clock import Clock
from ramp.common.hostport import parse_hostport
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

READ_CHUNK = 65536
READ_BUDGET = 1 << 18  # bytes per call at most: one chatty backend cannot stall a tick
_IN_PROGRESS = {errno.EINPROGRESS, errno.EWOULDBLOCK, errno.EALREADY, errno.EINTR}


class IoLoop(Protocol):
    """What the link needs from a loop (`ramp.scheduler.Scheduler` has it)."""

    def add_reader(self, fd: int, callback: Callable[[], None]) -> None: ...

    def remove_reader(self, fd: int) -> None: ...

    def add_writer(self, fd: int, callback: Callable[[], None]) -> None: ...

    def remove_writer(self, fd: int) -> None: ...


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
                 on_connect: Callable[[McpLink], None] | None = None) -> None:
        self.host, self.port = parse_backend(address)
        for label, value in (("reply_timeout", reply_timeout),
                             ("connect_timeout", connect_timeout),
                             ("backoff_min", backoff_min), ("backoff_max", backoff_max),
                             ("heartbeat_s", 1.0 if heartbeat_s is None else heartbeat_s)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: {label} must be a positive number of seconds")
        if backoff_max < backoff_min:
            raise ValueError(f"{name}: backoff_max is smaller than backoff_min")
        self.clock = clock
        self.loop = loop
        self.name = name
        self.reply_timeout = reply_timeout
        self.heartbeat_s = heartbeat_s
        self.connect_timeout = connect_timeout
        self.backoff_min = backoff_min
        self.backoff_max = backoff_max
        self.on_connect = on_connect
        #: Lines nobody asked for (a `busy` greeting), newest last, for the mission to read.
        self.unsolicited: list[bytes] = []
        self.stats = {"connects": 0, "connect_failures": 0, "disconnects": 0, "sent": 0,
                      "replies": 0, "heartbeats": 0, "timeouts": 0, "lost_requests": 0}
        self.state = STOPPED
        self.fault = ""
        self._session: McpSession[ReplyCallback | None] = McpSession()
        self._sock: socket.socket | None = None
        self._connecting = False
        self._connect_deadline = math.inf
        self._retry_at = 0.0
        self._backoff = backoff_min
        self._out = bytearray()
        self._writer = False
        self._last_sent = -math.inf
        self._sockaddr: tuple[int, tuple[object, ...]] | None = None

    # -- state ------------------------------------------------------------------------------
    @property
    def address(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"

    @property
    def connected(self) -> bool:
        return self.state == CONNECTED

    @property
    def in_flight(self) -> int:
        """Messages sent and not answered yet."""
        return self._session.in_flight

    def fileno(self) -> int:
        return self._sock.fileno() if self._sock is not None else -1

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self) -> None:
        """Begin connecting; returns at once (a host *name* is resolved here, once, which
        can wait on DNS: give the backend's IP address)."""
        if self.state != STOPPED:
            return
        now = self.clock.now()
        try:
            numeric = socket.AI_NUMERICHOST if _is_ip(self.host) else 0
            infos = socket.getaddrinfo(self.host, self.port, type=socket.SOCK_STREAM,
                                       flags=numeric)
        except OSError as exc:
            self._sockaddr = None
            self.stats["connect_failures"] += 1
            self._drop(now, f"cannot resolve {self.host!r}: {exc}")
            return
        family, _, _, _, sockaddr = infos[0]
        self._sockaddr = (family, tuple(sockaddr))
        self._connect(now)

    def tick(self, now: float, dt: float) -> None:
        if self.state == STOPPED:
            return
        if self._sock is None:
            if now >= self._retry_at:
                if self._sockaddr is None:
                    self.state = STOPPED
                    self.start()
                else:
                    self._connect(now)
            return
        if self._connecting:
            self._check_connect(now)
            return
        self.on_readable()
        if self._sock is None:
            return
        oldest = self._session.oldest_sent_at()
        if oldest is not None and now - oldest > self.reply_timeout:
            self.stats["timeouts"] += 1
            self._drop(now, f"no reply within {self.reply_timeout:g} s")
            return
        if self.heartbeat_s is not None and now - self._last_sent >= self.heartbeat_s:
            self.stats["heartbeats"] += 1
            self._write(b"", None, now)
        self._flush()

    def stop(self) -> None:
        """Close the connection (unanswered callbacks get an error reply); idempotent."""
        if self.state == STOPPED:
            return
        self._close_socket(self.clock.now(), "the link was stopped")
        self.state = STOPPED
        self._retry_at = 0.0
        self._backoff = self.backoff_min

    close = stop

    # -- requests ----------------------------------------------------------------------------
    def send(self, message: Message, on_reply: ReplyCallback | None = None) -> bool:
        """Write one message; False (and nothing sent) while not connected. ValueError for a
        message that is not one MCP message (see `ramp.mcp.session.encode_message`)."""
        if self.state != CONNECTED:
            return False
        self._write(message, on_reply, self.clock.now())
        return self._sock is not None

    def _write(self, message: Message, on_reply: ReplyCallback | None, now: float) -> None:
        self._out += self._session.send(message, on_reply, now)
        self._last_sent = now
        self.stats["sent"] += 1
        self._flush()

    # -- I/O ----------------------------------------------------------------------------------
    def on_readable(self) -> None:
        """Read what has arrived and hand each reply to its callback (never blocks)."""
        sock = self._sock
        if sock is None or self._connecting:
            return
        now = self.clock.now()
        budget = READ_BUDGET
        while budget > 0 and self._sock is sock:
            try:
                data = sock.recv(READ_CHUNK)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                self._drop(now, f"connection failed: {exc.strerror or exc}")
                return
            if not data:
                why = "the backend closed the connection"
                if self.unsolicited and b"busy" in self.unsolicited[-1]:
                    why = f"the backend is busy ({self.unsolicited[-1].decode('ascii', 'replace')})"
                self._drop(now, why)
                return
            budget -= len(data)
            for reply in self._session.feed(data, now):
                self._deliver(reply)

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

    def _flush(self) -> None:
        sock = self._sock
        if sock is None or self._connecting:
            return
        while self._out:
            try:
                n = sock.send(self._out)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                self._drop(self.clock.now(), f"sending failed: {exc.strerror or exc}")
                return
            del self._out[:n]
        self._want_writable(bool(self._out))

    def _on_writable(self) -> None:
        if self._connecting:
            self._check_connect(self.clock.now())
        else:
            self._flush()

    def _want_writable(self, on: bool) -> None:
        if self.loop is None or self._sock is None or on == self._writer:
            return
        if on:
            self.loop.add_writer(self._sock.fileno(), self._on_writable)
        else:
            self.loop.remove_writer(self._sock.fileno())
        self._writer = on

    # -- connecting ---------------------------------------------------------------------------
    def _connect(self, now: float) -> None:
        assert self._sockaddr is not None
        family, sockaddr = self._sockaddr
        try:
            sock = socket.socket(family, socket.SOCK_STREAM)
        except OSError as exc:
            self.stats["connect_failures"] += 1
            self._drop(now, f"cannot open a socket: {exc}")
            return
        sock.setblocking(False)
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        err = sock.connect_ex(sockaddr)
        self._sock = sock
        self.stats["connects"] += 1
        if err == 0:
            self._connected(now)
        elif err in _IN_PROGRESS:
            self._connecting = True
            self._connect_deadline = now + self.connect_timeout
            self.state = CONNECTING
            self._want_writable(True)
        else:
            self.stats["connect_failures"] += 1
            self._drop(now, f"cannot connect: {_strerror(err)}")

    def _check_connect(self, now: float) -> None:
        sock = self._sock
        assert sock is not None
        try:
            _, writable, _ = select.select([], [sock], [], 0)
        except (OSError, ValueError):
            writable = [sock]
        if writable:
            err = sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            if err == 0:
                self._connected(now)
            else:
                self.stats["connect_failures"] += 1
                self._drop(now, f"cannot connect: {_strerror(err)}")
        elif now >= self._connect_deadline:
            self.stats["connect_failures"] += 1
            self._drop(now, f"connect timed out after {self.connect_timeout:g} s")

    def _connected(self, now: float) -> None:
        self._connecting = False
        self._want_writable(False)
        sock = self._sock
        assert sock is not None
        if self.loop is not None:
            self.loop.add_reader(sock.fileno(), self.on_readable)
        self._session.reset()
        self.state = CONNECTED
        if self.fault:
            log.info("%s: connected to %s again (was: %s)", self.name, self.address,
                     self.fault)
        else:
            log.info("%s: connected to %s", self.name, self.address)
        self.fault = ""
        self._backoff = self.backoff_min
        self._last_sent = now
        if self.on_connect is not None:
            try:
                self.on_connect(self)
            except Exception:
                log.exception("%s: on_connect raised", self.name)

    # -- losing it ----------------------------------------------------------------------------
    def _drop(self, now: float, reason: str) -> None:
        if self.state == CONNECTED:
            self.stats["disconnects"] += 1
        self._close_socket(now, reason)
        self._retry_at = now + self._backoff
        self.fault = f"{self.name} at {self.address}: {reason}"
        log.warning("%s; retrying in %.2g s", self.fault, self._backoff)
        self._backoff = min(self._backoff * 2.0, self.backoff_max)
        self.state = DISCONNECTED

    def _close_socket(self, now: float, reason: str) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            if self.loop is not None:
                with contextlib.suppress(Exception):
                    self.loop.remove_reader(sock.fileno())
                if self._writer:
                    with contextlib.suppress(Exception):
                        self.loop.remove_writer(sock.fileno())
            with contextlib.suppress(OSError):
                sock.close()
        self._writer = False
        self._connecting = False
        self._out.clear()
        for pending in self._session.reset():
            self.stats["lost_requests"] += 1
            if pending.tag is not None:
                try:
                    pending.tag(Reply(b"", pending.request, pending.tag, pending.sent_at, now,
                                      error=f"connection lost: {reason}"))
                except Exception:
                    log.exception("%s: reply callback raised", self.name)


def _is_ip(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


def _strerror(err: int) -> str:
    return f"{errno.errorcode.get(err, str(err))} ({os.strerror(err)})"
