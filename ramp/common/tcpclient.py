"""A non-blocking TCP client with back-off, driven from one loop: the autonomy's MCP link and
the Hokuyo driver both stand on it.

It never blocks the loop that drives it: the connect is non-blocking (finished when the
socket turns writable, or checked from `tick`), bytes are read when the socket is readable
(`on_readable`, registered with the loop's `add_reader`, or polled from `tick`) at most
`READ_BUDGET` a call, and written without waiting (the rest when the socket is writable).
Whether more has arrived is asked of a `poll` object holding the one socket (no wait), not
learnt from a `recv` that fails with EWOULDBLOCK: `tick` looks every tick and usually finds
nothing, and a raised exception costs more than the question (the same bytes at the same
moments: a socket that polls unreadable is one whose `recv` would fail that way).
Every wait is a deadline checked in `tick(now)`; time comes from the injected `now`.

The owner speaks the protocol and is told three things: `on_connected(now)`, `on_data(data,
now)` for each chunk read, and `on_lost(now, reason)` after a connection (or an attempt) is
gone; `on_eof(now)` names why when the peer closes (a decoder may want to say what was cut
short). A lost connection or a failed attempt is retried after a back-off that doubles from
`backoff_min` up to `backoff_max`; the owner calls `reset_backoff()` when the peer has proven
itself (a connect for MCP, a finished handshake for a LIDAR). `drop(now, reason)` closes and
retries, `close()` closes for good until the next `start()`.

The socket is closed and the client's state says so *before* `on_lost` runs, so nothing the
owner does from there (failing its callbacks, which may try to send) can write into a dead
connection or leave bytes for the next one: `write` while not connected is refused.

A host *name* is resolved in `start()` (and again after `set_address`), which can wait on
DNS: give an IP address where it matters.
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import math
import os
import select
import socket
import ssl
from collections.abc import Callable
from typing import Protocol

from ramp.common.hostport import format_hostport

READ_CHUNK = 65536
READ_BUDGET = 1 << 18  # bytes per call at most: one chatty peer cannot stall a tick
_IN_PROGRESS = {errno.EINPROGRESS, errno.EWOULDBLOCK, errno.EALREADY, errno.EINTR}

IDLE = "idle"  # not started, or closed
WAITING = "waiting"  # between attempts (back-off)
CONNECTING = "connecting"
CONNECTED = "connected"


class IoLoop(Protocol):
    """What the client needs from a loop (`ramp.scheduler.Scheduler` has it)."""

    def add_reader(self, fd: int, callback: Callable[[], None]) -> None: ...

    def remove_reader(self, fd: int) -> None: ...

    def add_writer(self, fd: int, callback: Callable[[], None]) -> None: ...

    def remove_writer(self, fd: int) -> None: ...


def check_seconds(name: str, **seconds: float) -> None:
    """Every timing given must be a positive number of seconds, and `backoff_max` (when
    given) at least `backoff_min`; ValueError naming the owner and the setting."""
    for label, value in seconds.items():
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name}: {label} must be a positive number of seconds")
    if seconds.get("backoff_max", math.inf) < seconds.get("backoff_min", 0.0):
        raise ValueError(f"{name}: backoff_max is smaller than backoff_min")


def _nothing(*_: object) -> None:
    return None


class TcpClient:
    """One TCP peer, reconnected with back-off; `tick(now)` from a scheduler task."""

    def __init__(self, host: str, port: int, *, now: Callable[[], float],
                 loop: IoLoop | None = None, connect_timeout: float = 2.0,
                 backoff_min: float = 0.5, backoff_max: float = 8.0,
                 on_connected: Callable[[float], None] = _nothing,
                 on_data: Callable[[bytes, float], None] = _nothing,
                 on_lost: Callable[[float, str], None] = _nothing,
                 on_eof: Callable[[float], str] | None = None,
                 connect_hint: str = "",
                 stats: dict[str, int] | None = None,
                 ssl_context: ssl.SSLContext | None = None) -> None:
        self.host, self.port = host, port
        #: TLS (`mcps://`, SPEC 13): after the TCP connect, a handshake, driven like the
        #: connect (never blocking, under the same deadline); the peer is told `connected`
        #: only once it is done.
        self.ssl_context = ssl_context
        self._handshaking = False
        self.now = now
        self.loop = loop
        self.connect_timeout = connect_timeout
        self.backoff_min = backoff_min
        self.backoff_max = backoff_max
        self.on_connected = on_connected
        self.on_data = on_data
        self.on_lost = on_lost
        self.on_eof = on_eof
        self.connect_hint = connect_hint  # added to a connect time-out ("is it on the network?")
        #: connects (attempts), connect_failures, disconnects (established connections lost).
        self.stats = stats if stats is not None else {}
        for key in ("connects", "connect_failures", "disconnects"):
            self.stats.setdefault(key, 0)
        self.state = IDLE
        #: The back-off the next failure waits (after it, doubled).
        self.backoff = backoff_min
        self.retry_at = 0.0
        self._sock: socket.socket | None = None
        self._sockaddr: tuple[int, tuple[object, ...]] | None = None
        self._connect_deadline = math.inf
        self._out = bytearray()
        self._writer = False
        #: Polls the connected socket for input (or its end): `select.poll().poll`.
        self._poll_in: Callable[[int], list[tuple[int, int]]] | None = None

    # -- state ----------------------------------------------------------------------------------
    @property
    def address(self) -> str:
        return format_hostport(self.host, self.port)

    @property
    def connected(self) -> bool:
        return self.state == CONNECTED

    @property
    def pending_out(self) -> int:
        """Bytes written and not yet taken by the kernel."""
        return len(self._out)

    def fileno(self) -> int:
        """The socket's descriptor, -1 when there is none."""
        return self._sock.fileno() if self._sock is not None else -1

    def set_address(self, host: str, port: int) -> None:
        """Talk to another peer from the next attempt on (resolved again then)."""
        self.host, self.port = host, port
        self._sockaddr = None

    def reset_backoff(self) -> None:
        self.backoff = self.backoff_min

    # -- lifecycle ------------------------------------------------------------------------------
    def start(self) -> None:
        """Resolve the host and begin connecting; returns at once after the resolve."""
        if self.state != IDLE:
            return
        self.state = WAITING
        self._attempt(self.now())

    def tick(self, now: float) -> None:
        """Retry when the back-off is over, finish a connect, read what has arrived."""
        if self.state == WAITING:
            if now >= self.retry_at:
                self._attempt(now)
        elif self.state == CONNECTING:
            if self._handshaking:
                self._handshake(now)
            else:
                self._check_connect(now)
        elif self.state == CONNECTED:
            poll_in = self._poll_in
            if poll_in is None or poll_in(0) or _buffered(self._sock):
                self.on_readable()
            if self._out or self._writer:
                self.flush()

    def drop(self, now: float, reason: str) -> None:
        """Close the connection (or attempt), retry after the back-off, tell `on_lost`."""
        if self.state == IDLE:
            return
        if self.state == CONNECTED:
            self.stats["disconnects"] += 1
        self._close_socket()
        self.state = WAITING
        self.retry_at = now + self.backoff
        self.backoff = min(self.backoff * 2.0, self.backoff_max)
        self.on_lost(now, reason)

    def close(self) -> None:
        """Close for good (until `start()`); `on_lost` is not called. Idempotent."""
        self._close_socket()
        self.state = IDLE
        self.retry_at = 0.0
        self.backoff = self.backoff_min

    # -- bytes ----------------------------------------------------------------------------------
    def write(self, data: bytes) -> bool:
        """Queue `data` and send what the kernel takes now; False (nothing queued) when not
        connected."""
        if self.state != CONNECTED:
            return False
        self._out += data
        self.flush()
        return True

    def flush(self) -> None:
        sock = self._sock
        if sock is None or self.state != CONNECTED:
            return
        while self._out:
            try:
                n = sock.send(self._out)
            except (BlockingIOError, InterruptedError, ssl.SSLWantWriteError,
                    ssl.SSLWantReadError):
                break
            except OSError as exc:
                self.drop(self.now(), f"sending failed: {exc.strerror or exc}")
                return
            del self._out[:n]
        self._want_writable(bool(self._out))

    def on_readable(self) -> None:
        """Read what has arrived and hand it to `on_data` (never blocks)."""
        sock = self._sock
        if sock is None or self.state != CONNECTED:
            return
        now = self.now()
        budget = READ_BUDGET
        poll_in = self._poll_in
        first = True
        while budget > 0 and self._sock is sock:
            if not first and poll_in is not None and not poll_in(0) and not _buffered(sock):
                return  # nothing more has arrived (what a failing recv would say)
            first = False
            try:
                data = sock.recv(READ_CHUNK)
            except (BlockingIOError, InterruptedError, ssl.SSLWantReadError,
                    ssl.SSLWantWriteError):
                return
            except OSError as exc:
                self.drop(now, f"connection failed: {exc.strerror or exc}")
                return
            if not data:
                reason = self.on_eof(now) if self.on_eof is not None \
                    else "the peer closed the connection"
                if self._sock is sock:
                    self.drop(now, reason)
                return
            budget -= len(data)
            self.on_data(data, now)

    # -- connecting -----------------------------------------------------------------------------
    def _attempt(self, now: float) -> None:
        if self._sockaddr is None:
            try:
                numeric = socket.AI_NUMERICHOST if _is_ip(self.host) else 0
                infos = socket.getaddrinfo(self.host, self.port, type=socket.SOCK_STREAM,
                                           flags=numeric)
            except OSError as exc:
                self._failed(now, f"cannot resolve the host {self.host!r}: {exc}")
                return
            found, _, _, _, sockaddr = infos[0]
            self._sockaddr = (int(found), tuple(sockaddr))
        family, address = self._sockaddr
        try:
            sock = socket.socket(family, socket.SOCK_STREAM)
        except OSError as exc:
            self._failed(now, f"cannot open a socket: {exc}")
            return
        sock.setblocking(False)
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        err = sock.connect_ex(address)
        self._sock = sock
        self.stats["connects"] += 1
        if err == 0:
            self._tcp_connected(now)
        elif err in _IN_PROGRESS:
            self.state = CONNECTING
            self._connect_deadline = now + self.connect_timeout
            self._want_writable(True)
        else:
            self._failed(now, f"cannot connect: {_strerror(err)}")

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
                self._tcp_connected(now)
            else:
                self._failed(now, f"cannot connect: {_strerror(err)}")
        elif now >= self._connect_deadline:
            hint = f" ({self.connect_hint})" if self.connect_hint else ""
            self._failed(now, f"connect timed out after {self.connect_timeout:.1f} s{hint}")

    def _tcp_connected(self, now: float) -> None:
        """TCP is up: connected, or (TLS) the handshake begins under the connect's deadline."""
        if self.ssl_context is None:
            self._connected(now)
            return
        sock = self._sock
        assert sock is not None
        self._want_writable(False)
        try:
            self._sock = self.ssl_context.wrap_socket(
                sock, server_hostname=self.host, do_handshake_on_connect=False)
        except (ssl.SSLError, OSError) as exc:
            self._failed(now, f"TLS failed: {exc}")
            return
        self.state = CONNECTING
        self._handshaking = True
        self._connect_deadline = now + self.connect_timeout
        self._handshake(now)

    def _handshake(self, now: float) -> None:
        sock = self._sock
        assert isinstance(sock, ssl.SSLSocket)
        try:
            sock.do_handshake()
        except ssl.SSLWantReadError:
            self._want_writable(False)
        except ssl.SSLWantWriteError:
            self._want_writable(True)
        except ssl.SSLCertVerificationError as exc:
            self._failed(now, f"the robot's certificate is not trusted: {exc.verify_message} "
                              "(is --ca the robot's CA, and the host a name or address "
                              "its certificate was made for?)")
            return
        except (ssl.SSLError, OSError) as exc:
            self._failed(now, f"TLS handshake failed: {getattr(exc, 'reason', None) or exc} "
                              "(does the robot accept this certificate?)")
            return
        else:
            self._handshaking = False
            self._connected(now)
            return
        if now >= self._connect_deadline:
            self._failed(now, f"TLS handshake timed out after {self.connect_timeout:.1f} s")

    def _failed(self, now: float, reason: str) -> None:
        self.stats["connect_failures"] += 1
        self.drop(now, reason)

    def _connected(self, now: float) -> None:
        sock = self._sock
        assert sock is not None
        self._want_writable(False)
        self._out.clear()
        self.state = CONNECTED
        poller = select.poll()
        poller.register(sock.fileno(), select.POLLIN | select.POLLPRI)
        self._poll_in = poller.poll
        if self.loop is not None:
            self.loop.add_reader(sock.fileno(), self.on_readable)
        self.on_connected(now)

    def _on_writable(self) -> None:
        if self.state == CONNECTING and self._handshaking:
            self._handshake(self.now())
        elif self.state == CONNECTING:
            self._check_connect(self.now())
        else:
            self.flush()

    def _want_writable(self, on: bool) -> None:
        if self.loop is None or self._sock is None or on == self._writer:
            return
        if on:
            self.loop.add_writer(self._sock.fileno(), self._on_writable)
        else:
            self.loop.remove_writer(self._sock.fileno())
        self._writer = on

    def _close_socket(self) -> None:
        sock, self._sock = self._sock, None
        self._poll_in = None
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
        self._handshaking = False
        self._out.clear()
        if self.state in (CONNECTING, CONNECTED):
            self.state = WAITING


def _buffered(sock: socket.socket | None) -> bool:
    """Decrypted bytes TLS holds that a poll of the descriptor cannot see."""
    return isinstance(sock, ssl.SSLSocket) and sock.pending() > 0


def _is_ip(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


def _strerror(err: int) -> str:
    return f"{errno.errorcode.get(err, str(err))} ({os.strerror(err)})"
