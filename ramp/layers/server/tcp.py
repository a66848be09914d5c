"""Server layer: non-blocking MCP over TCP, serviced by the scheduler between ticks.

This layer owns framing and parsing: it splits a client's bytes into messages, parses each
one (`ramp.mcp.protocol`) and hands it down to the robot distribution layer as requests with
a `RequestContext` (the client and the time the message was taken up), then writes the one
answer line back. It decides nothing about the robot.

One response line per request line, in order, per client. A client that stops reading is
cut off once its unsent output passes a bound, so it can never block the loop or grow memory.
Work is bounded by time (SPEC 2.2, *Bounded work*): a client's turn reads at most one small
chunk, then answers its queued messages request by request until the tick's deadline (or a
short slice, so other clients interleave); whatever is left, even half a message, is taken up
again in its next turn, after the tick. A client that half-closes (sends FIN) is treated as
gone for the watchdog and arbitration at once, but still receives every answer it is owed.

Answers given again: a client repeats the same few lines (a poll of `base.get`) thousands of
times, and a read answered by its function's `line` is a pure function of the robot's state
version (`ramp.layers.robot_distribution`). Such an answer is kept by the message's bytes; a
read that brings exactly that message, whole, with nothing held before it, while the version
is the one it was made at, is answered with the kept line without parsing or routing. The
message is still heard (the watchdog) and observed (the recorder's hooks).
"""

from __future__ import annotations

import contextlib
import errno
import functools
import logging
import math
import socket
import ssl
from collections import deque
from collections.abc import Callable

from ramp.common.access import RANK, AccessConfig, is_loopback
from ramp.common.hostport import format_hostport
from ramp.layers.module_distribution.router import Version
from ramp.layers.robot_distribution import Client, RequestContext, RobotDistribution
from ramp.layers.server.gate import (
    HANDSHAKE_S,
    MAX_PENDING,
    TLS_HANDSHAKE_RECORD,
    Pending,
    certificate_identity,
    choose_victim,
)
from ramp.mcp.messages import Request, error_response
from ramp.mcp.protocol import (
    LineSplitter,
    TooLong,
    format_response,
    parse_message,
    too_long_response,
)
from ramp.scheduler import ScheduledTask, Scheduler

log = logging.getLogger("ramp.server")

# One read per turn: 64 KiB once held the loop for 300 ms (about 5 us per byte of bare newlines
# or gets), long enough for the stall guard to stop every motor. The rest waits in the kernel,
# and select reports the socket readable again on the next pass.
READ_CHUNK = 1024
#: Longest a client's turn lasts even when the tick is far off, so other clients interleave.
TURN_S = 0.002
#: Always room for a stop (SPEC 2.2): with every slot taken, a newcomer evicts the client
#: silent longest if it has sent no complete message for this long and is neither the owner
#: nor a commander of a moving module (evicting one would stop the robot), so an operator can
#: always connect and send robot:robot.stop=().
EVICT_SILENCE_S = 5.0
#: Out of file descriptors (EMFILE): stop accepting for this long instead of spinning (the
#: listening socket stays readable, and accept failed 130,924 times in 10 s); the client
#: waits in the listen backlog meanwhile.
ACCEPT_BACKOFF_S = 0.1
_OUT_OF_FDS = (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM)
#: Descriptors the process needs besides its clients: stdio, the listening socket, logs, and
#: each bus's port (a pty or USB adapter, a CAN socket, a vendor library's own).
FD_RESERVE = 32
FD_PER_BUS = 4
#: Messages up to this long are kept parsed (at most this many), keyed by their bytes.
PARSE_CACHE_LINE = 256
PARSE_CACHE_SIZE = 512


class Connection(Client):
    """One TCP client: its socket, input splitter, the message being answered, output."""

    def __init__(self, sock: socket.socket, peer: str, max_line: int, now: float,
                 address: str = "", identity: str = "local", role: str = "admin",
                 tls: bool = False, serial: int | None = None) -> None:
        super().__init__(peer, identity, role, tls)
        #: The remote address without its port (per-address caps, SPEC 13).
        self.address = address
        #: Its certificate's serial (revocation on SIGHUP), None for a plain client.
        self.serial = serial
        #: When its last complete message arrived (or when it connected).
        self.last_message_at = now
        self.sock = sock
        self.fd = sock.fileno()
        self.splitter = LineSplitter(max_line)
        #: Complete messages read and not yet answered, oldest first.
        self.queue: deque[bytes | TooLong] = deque()
        #: The message being answered, request by request: its context, its requests, the
        #: next one's index, the answer so far and what ends it (a syntax error, or nothing).
        self.ctx: RequestContext | None = None
        self.requests: tuple[Request, ...] = ()
        self.index = 0
        self.answer: list[bytes] = []
        self.tail = b""
        self.out = bytearray()
        self.writing = False  # registered as a writer: output is waiting for room
        self.closed = False
        #: The client sent FIN: nothing more to read, answers still to deliver.
        self.input_ended = False
        self.lost_reported = False


#: Observer hooks: (client, clock time, the message as it arrived, or TooLong) for every
#: complete message in, and (client, clock time, the answer line) for every line out.
MessageInHook = Callable[[Client, float, "bytes | TooLong"], None]
MessageOutHook = Callable[[Client, float, bytes], None]
#: An answer the server may give again: (the version it was made at, the message, the line).
KeptAnswer = tuple[Version, bytes, bytes]


class McpServer:
    """Accepts clients, frames and parses their messages, hands each one down to the robot
    layer with its request context, and writes the answers back."""

    def __init__(self, scheduler: Scheduler, robot: RobotDistribution,
                 host: str = "127.0.0.1", port: int = 5577, max_clients: int = 8,
                 max_line: int = 4096, max_output: int = 1 << 20,
                 tls: ssl.SSLContext | None = None,
                 access: AccessConfig | None = None) -> None:
        self.scheduler = scheduler
        self.robot = robot
        self.host = host
        self.port = port
        self.max_clients = max_clients
        self.max_line = max_line
        self.max_output = max_output
        # max_line already bounds a message's work; every well-formed one fits (>= 8 bytes)
        self.max_requests = max(256, max_line // 8 + 1)
        self.clients: dict[int, Connection] = {}
        self.sock: socket.socket | None = None
        self.accepted = 0
        self.refused = 0
        self.evicted = 0
        self.accept_failures = 0
        #: Observer hooks (the flight recorder): None costs nothing.
        self.on_message_in: MessageInHook | None = None
        self.on_message_out: MessageOutHook | None = None
        self._accept_paused_until: float | None = None
        self._resume_task: ScheduledTask | None = None
        self._accept_failures_logged = 0
        self._now = scheduler.clock.now
        self._pending_fds = scheduler.pending
        self._too_long = format_response(too_long_response(max_line)).encode("ascii")
        #: Parsed short messages by their bytes: parsing is a pure function of them, and a
        #: client repeats the same few lines (a poll, a heartbeat) thousands of times.
        self._parsed: dict[bytes, tuple[tuple[Request, ...], bytes]] = {}
        #: Answers to give again (`_keep`), by the message's bytes (a message taken from the
        #: splitter), and by them with their `\n` (one read bringing exactly that message,
        #: ended): two tables, so a read of a message not yet ended is never answered.
        self._answers: dict[bytes, KeptAnswer] = {}
        self._answers_read: dict[bytes, KeptAnswer] = {}
        #: Mutual TLS (SPEC 13): the robot's context, None for plain TCP only.
        self.tls = tls
        self.access = access if access is not None else AccessConfig()
        #: Connections not yet admitted (first byte unread, or a TLS handshake), by fd.
        self.pending: dict[int, Pending] = {}
        self._pending_task: ScheduledTask | None = None
        self.handshakes_failed = 0
        self._handshake_failures_logged = 0

    @property
    def address(self) -> tuple[str, int]:
        assert self.sock is not None
        host, port = self.sock.getsockname()[:2]
        return host, port

    def start(self) -> None:
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((self.host, self.port))
        # Room for every client to connect at once (a burst past the backlog waits 1 s for
        # TCP to retry its SYN).
        sock.listen(max(64, min(self.max_clients + 16, socket.SOMAXCONN)))
        sock.setblocking(False)
        self.sock = sock
        self.scheduler.add_reader(sock.fileno(), self._accept)

    def _resume_accepting(self, now: float, dt: float) -> None:
        """Scheduler task while accepting is paused: accept again once the back-off after
        running out of descriptors is over (the task then removes itself)."""
        if self._accept_paused_until is not None and now >= self._accept_paused_until:
            self._accept_paused_until = None
            if self._resume_task is not None:
                self.scheduler.remove_task(self._resume_task)
                self._resume_task = None
            if self.sock is not None:
                self.scheduler.add_reader(self.sock.fileno(), self._accept)

    @property
    def accept_paused(self) -> bool:
        return self._accept_paused_until is not None

    def close(self) -> None:
        for p in list(self.pending.values()):
            self._close_pending(p, "server shutting down")
        for conn in list(self.clients.values()):
            self._drop(conn, "server shutting down")
        if self.sock is not None:
            self.scheduler.remove_reader(self.sock.fileno())
            self.sock.close()
            self.sock = None

    # -- accepting ----------------------------------------------------------------------------
    def _accept(self) -> None:
        assert self.sock is not None
        for _ in range(16):  # bounded: a connect storm cannot starve the tick
            try:
                sock, addr = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                self._accept_failed(exc)
                return
            peer = format_hostport(addr[0], addr[1])  # [::1]:41234, as clients take it
            address = str(addr[0])
            loopback = is_loopback(address)
            if self.tls is not None:
                self._start_pending(sock, address, peer, loopback)
                continue
            role = self._plain_role(loopback)
            if role is None:
                _say_and_close(sock, b"robot:mcp.error=(forbidden,plain MCP is not accepted "
                               b"here: connect with mcps:// and a client certificate)\n")
                continue
            self._admit(sock, peer, address, "local", role, False, None)

    def _plain_role(self, loopback: bool) -> str | None:
        """The role of a client that speaks plain MCP (SPEC 13), or None: refused."""
        access = self.access
        if not access.configured or access.allow_anonymous:
            return "admin" if loopback or access.allow_anonymous else None
        if not loopback or access.local == "none":
            return None
        return access.local

    def _admit(self, sock: socket.socket, peer: str, address: str, identity: str, role: str,
               tls: bool, serial: int | None) -> None:
        """A connection that is what it says: give it a slot (making room if its role may),
        or tell it `busy` and close it."""
        now = self.scheduler.clock.now()
        if not self._make_room(peer, address, identity, role, tls, now):
            self.refused += 1
            _say_and_close(sock, b"robot:mcp.error=(busy,too many clients; at most "
                           + str(self.max_clients).encode() + b")\n")
            return
        sock.setblocking(False)
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn = Connection(sock, peer, self.max_line, now, address, identity, role, tls,
                          serial)
        self.clients[conn.fd] = conn
        self.accepted += 1
        self.scheduler.add_reader(conn.fd, functools.partial(self._readable, conn))
        who = f" as {identity} ({role})" if tls or self.access.configured else ""
        log.info("client %s connected%s (%d of %d)", peer, who, len(self.clients),
                 self.max_clients)

    def _make_room(self, peer: str, address: str, identity: str, role: str, tls: bool,
                   now: float) -> bool:
        """SPEC 13's caps: per identity (a newcomer replaces its own identity's longest-silent
        connection: a laptop that lost Wi-Fi reconnects), per remote address and in all (an
        operator or admin evicts an observer or unauthenticated connection; others get
        `busy`)."""
        access = self.access
        if tls:
            same = [c for c in self.clients.values() if c.tls and c.identity == identity]
            if len(same) >= access.max_per_identity:
                self._evict(min(same, key=_silence_key), peer, now,
                            f"access.max_per_identity {access.max_per_identity}")
            here = [c for c in self.clients.values() if c.tls and c.address == address]
            if len(here) >= access.max_per_address:
                victim = choose_victim(role, here, _silence_key, self.robot.protects, now,
                                       EVICT_SILENCE_S, authenticated=True)
                if victim is None and RANK.get(role, 0) < RANK["operator"]:
                    log.warning("refused %s as %s: its address holds %d connections "
                                "(access.max_per_address)", peer, identity, len(here))
                    return False
                if victim is not None:
                    self._evict(victim, peer, now,
                                f"access.max_per_address {access.max_per_address}")
        if len(self.clients) < self.max_clients:
            return True
        victim = choose_victim(role, self.clients.values(), _silence_key, self.robot.protects,
                               now, EVICT_SILENCE_S, roles=access.configured,
                               authenticated=tls)
        if victim is None:
            log.warning("refused %s: already %d clients (server.max_clients), none silent "
                        "for %.0f s that is neither owner nor commanding a moving module", peer,
                        len(self.clients), EVICT_SILENCE_S)
            return False
        self._evict(victim, peer, now, f"server.max_clients {self.max_clients}")
        return True

    def _evict(self, victim: Client, newcomer: str, now: float, cap: str) -> None:
        assert isinstance(victim, Connection)
        quiet = now - victim.last_message_at
        log.warning("client %s evicted: no message for %.1f s and %s needed its slot (%s)",
                    victim.peer, quiet, newcomer, cap)
        self.evicted += 1
        self._drop(victim, f"evicted after {quiet:.1f} s of silence",
                   farewell=b"robot:mcp.error=(busy,closed to make room for another client: "
                   + f"no message for {quiet:.0f} s".encode() + b")\n")

    def reload_access(self, access: AccessConfig, tls: ssl.SSLContext | None) -> list[str]:
        """New identities, roles, revocations and caps (SIGHUP, SPEC 13): every connected
        client keeps its connection with its new role, except one whose certificate is now
        revoked or whose identity is gone, which is dropped at once (losing a commander
        trips the watchdog). Returns the peers dropped."""
        self.access = access
        if tls is not None:
            self.tls = tls
        dropped = []
        for conn in list(self.clients.values()):
            if conn.tls:
                role = access.role_of(conn.identity)
                why = ("its certificate is revoked" if conn.serial in access.revoked else
                       "its identity left access.identities" if role is None else "")
            else:
                role = self._plain_role(is_loopback(conn.address))
                why = "plain clients are no longer accepted" if role is None else ""
            if why:
                dropped.append(conn.peer)
                log.warning("client %s (%s) dropped: %s", conn.peer, conn.identity, why)
                self._drop(conn, why, farewell=b"robot:mcp.error=(forbidden,"
                           + why.encode() + b")\n")
            elif role is not None and role != conn.role:
                log.info("client %s (%s) is now %s", conn.peer, conn.identity, role)
                conn.role = role
        return dropped

    # -- the gate: first byte, TLS handshake (SPEC 13) ----------------------------------------
    def _start_pending(self, sock: socket.socket, address: str, peer: str,
                       loopback: bool) -> None:
        """Hold a new connection on a TLS port until it proves who it is. It holds no slot;
        too many in progress (in all, or from its address) replace the oldest."""
        now = self.scheduler.clock.now()
        # A silent loopback connection that may speak plain MCP is a local client yet to
        # talk (`nc`, a shell waiting for its user): it waits without a deadline, bounded
        # only by MAX_PENDING. Everything else must finish a handshake in HANDSHAKE_S.
        patient = loopback and self._plain_role(True) is not None
        mine = [p for p in self.pending.values() if p.address == address and not p.patient]
        if mine and len(mine) + sum(1 for c in self.clients.values() if c.tls and
                                    c.address == address) >= self.access.max_per_address:
            self._close_pending(min(mine, key=lambda p: p.started), "replaced by a newer "
                                "handshake from its address (access.max_per_address)")
        if len(self.pending) >= MAX_PENDING:
            self._close_pending(min(self.pending.values(), key=lambda p: p.started),
                                f"replaced by a newer handshake ({MAX_PENDING} in progress)")
        sock.setblocking(False)
        p = Pending(sock, sock.fileno(), address, peer, loopback, now,
                    math.inf if patient else now + HANDSHAKE_S, patient=patient)
        self.pending[p.fd] = p
        self.scheduler.add_reader(p.fd, functools.partial(self._pending_step, p))
        if self._pending_task is None:
            self._pending_task = self.scheduler.add_task(
                "server.handshakes", min(10.0, self.scheduler.rate_hz), self._expire_pending)

    def _pending_step(self, p: Pending) -> None:
        """Readiness of a pending connection: read its first byte, then drive the handshake."""
        if p.closed:
            return
        if p.tls is None:
            sock = p.sock
            assert isinstance(sock, socket.socket)
            try:
                first = sock.recv(1, socket.MSG_PEEK)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                self._close_pending(p, f"read error: {exc.strerror or exc}")
                return
            if not first:
                self._close_pending(p, "closed before its handshake")
                return
            if first[0] != TLS_HANDSHAKE_RECORD:
                self._plain_on_tls_port(p)
                return
            assert self.tls is not None
            if p.patient:  # it speaks TLS after all: now it has a handshake's time
                p.patient = False
                p.deadline = self.scheduler.clock.now() + HANDSHAKE_S
            try:
                p.tls = self.tls.wrap_socket(sock, server_side=True,
                                             do_handshake_on_connect=False)
            except (ssl.SSLError, OSError) as exc:
                self._close_pending(p, f"TLS failed: {exc}")
                return
            p.sock = p.tls
        self._handshake(p)

    def _handshake(self, p: Pending) -> None:
        tls = p.tls
        assert tls is not None
        try:
            tls.do_handshake()
        except ssl.SSLWantReadError:
            self._pending_wants_write(p, False)
            return
        except ssl.SSLWantWriteError:
            self._pending_wants_write(p, True)
            return
        except (ssl.SSLError, OSError, ValueError) as exc:
            self._handshake_failed(p, exc)
            return
        identity, serial = certificate_identity(tls)
        access = self.access
        why = ""
        role = access.role_of(identity)
        if serial is not None and serial in access.revoked:
            why = f"certificate {serial:#x} of {identity} is revoked (access.revoked)"
        elif role is None:
            why = f"{identity or 'a certificate without a CN'} is not in access.identities"
        self._forget_pending(p)
        if why:
            self.handshakes_failed += 1
            log.warning("refused %s: %s", p.peer, why)
            _say_and_close(tls, b"robot:mcp.error=(forbidden,"
                           + why.replace(",", ";").replace(")", "]").encode("ascii", "replace")
                           + b")\n")
            return
        assert role is not None
        self._admit(tls, p.peer, p.address, identity, role, True, serial)

    def _plain_on_tls_port(self, p: Pending) -> None:
        """Plain MCP on the TLS port: loopback may (SPEC 13, role `access.local`); anyone
        else is told to use TLS, and never reaches the parser."""
        role = self._plain_role(p.loopback)
        sock = p.sock
        assert isinstance(sock, socket.socket)
        self._forget_pending(p)
        if role is None:
            log.warning("refused %s: plain MCP on the TLS port", p.peer)
            _say_and_close(sock, b"robot:mcp.error=(forbidden,this port speaks TLS: connect "
                           b"with mcps:// and a client certificate)\n")
            return
        self._admit(sock, p.peer, p.address, "local", role, False, None)

    def _pending_wants_write(self, p: Pending, write: bool) -> None:
        if write and not p.writing:
            p.writing = True
            self.scheduler.add_writer(p.fd, functools.partial(self._pending_step, p))
        elif not write and p.writing:
            p.writing = False
            self.scheduler.remove_writer(p.fd)

    def _handshake_failed(self, p: Pending, exc: Exception) -> None:
        self.handshakes_failed += 1
        reason = getattr(exc, "reason", None) or type(exc).__name__
        # A flood of bad handshakes is one line now and then, not one per connection.
        if self.handshakes_failed - self._handshake_failures_logged >= 100 or \
                self._handshake_failures_logged == 0:
            log.warning("TLS handshake from %s failed: %s (%d failed so far)", p.peer,
                        reason, self.handshakes_failed)
            self._handshake_failures_logged = self.handshakes_failed
        self._close_pending(p, f"handshake failed: {reason}")

    def _expire_pending(self, now: float, dt: float) -> None:
        """Scheduler task while handshakes are in progress: each has HANDSHAKE_S."""
        for p in [p for p in self.pending.values() if now >= p.deadline]:
            self.handshakes_failed += 1
            self._close_pending(p, f"no handshake within {HANDSHAKE_S:g} s")
        if not self.pending and self._pending_task is not None:
            self.scheduler.remove_task(self._pending_task)
            self._pending_task = None

    def _forget_pending(self, p: Pending) -> None:
        """Out of the pending set (admitted, refused or closed); its fd's callbacks go."""
        self.pending.pop(p.fd, None)
        self.scheduler.remove_reader(p.fd)
        if p.writing:
            p.writing = False
            self.scheduler.remove_writer(p.fd)

    def _close_pending(self, p: Pending, why: str) -> None:
        if p.closed:
            return
        p.closed = True
        self._forget_pending(p)
        with contextlib.suppress(OSError):
            p.sock.close()  # type: ignore[attr-defined]
        log.debug("connection %s closed before admission: %s", p.peer, why)

    def _accept_failed(self, exc: OSError) -> None:
        self.accept_failures += 1
        if exc.errno not in _OUT_OF_FDS:
            log.error("accept failed: %s", exc)
            return
        assert self.sock is not None
        self.scheduler.remove_reader(self.sock.fileno())
        self._accept_paused_until = self.scheduler.clock.now() + ACCEPT_BACKOFF_S
        if self._resume_task is None:
            self._resume_task = self.scheduler.add_task(
                "server.accept", self.scheduler.rate_hz, self._resume_accepting)
        if self.accept_failures - self._accept_failures_logged >= 100 or \
                self._accept_failures_logged == 0:
            log.error("accept failed: %s (%d clients connected); new clients wait in the "
                      "backlog, accepting again in %.0f ms (%d failures so far)",
                      exc.strerror or exc, len(self.clients), ACCEPT_BACKOFF_S * 1e3,
                      self.accept_failures)
            self._accept_failures_logged = self.accept_failures

    # -- reading and answering ----------------------------------------------------------------
    def _readable(self, conn: Connection) -> None:
        """A client's turn: read one chunk unless work is left over, then answer in time."""
        now = self._now()
        end = min(self.scheduler.io_deadline, now + TURN_S)
        if conn.ctx is None and not conn.queue:
            try:
                data = conn.sock.recv(READ_CHUNK)
            except (BlockingIOError, InterruptedError, ssl.SSLWantReadError,
                    ssl.SSLWantWriteError):
                return
            except OSError as exc:
                self._drop(conn, f"read error: {exc.strerror or exc}")
                return
            if not data:
                self._end_input(conn)
                return
            again = self._answers_read.get(data)
            if again is not None and again[0] == self.robot.version and conn.splitter.empty:
                self._answer_again(conn, now, again)
            else:
                messages = conn.splitter.feed(data)
                if messages:
                    conn.last_message_at = now
                    conn.queue.extend(messages)
                self._work(conn, now, end)
        else:
            self._work(conn, now, end)
        if conn.closed:
            return
        more = conn.ctx is not None or bool(conn.queue)
        if conn.tls and not more:  # decrypted bytes TLS holds that select cannot see
            more = conn.sock.pending() > 0  # type: ignore[attr-defined]
        if more or conn.fd in self._pending_fds:
            self.scheduler.set_pending(conn.fd, more)
        self._flush(conn)

    def _parse(self, msg: bytes) -> tuple[tuple[Request, ...], bytes]:
        """A message's requests and what ends its answer (a syntax error, or nothing)."""
        parsed = self._parsed.get(msg)
        if parsed is None:
            requests, error = parse_message(msg, max_requests=self.max_requests)
            tail = format_response(error).encode("ascii") if error is not None else b""
            parsed = (requests, tail)
            if len(msg) <= PARSE_CACHE_LINE:
                if len(self._parsed) >= PARSE_CACHE_SIZE:
                    self._parsed.clear()
                self._parsed[msg] = parsed
        return parsed

    def _answer_again(self, conn: Connection, now: float, again: KeptAnswer) -> None:
        """A message answered before, whole in one read, while the version that answer was
        made at still holds: the same line again, without parsing or routing it. Everything
        else is as for any message (heard, observed)."""
        _, msg, line = again
        conn.last_message_at = now
        self.robot.heard(conn, now)
        if self.on_message_in is not None:
            self.on_message_in(conn, now, msg)
        conn.out += line
        conn.out += b"\n"
        if self.on_message_out is not None:
            self.on_message_out(conn, now, line)

    def _keep(self, msg: bytes, req: Request, version: Version, line: bytes) -> None:
        """Keep a one-request message's answer if it is the version's to give again."""
        robot = self.robot
        # Not one ending in `\r`: its bytes with `\n` are another message's (`\r\n` ends one).
        if len(msg) <= PARSE_CACHE_LINE and msg[-1:] != b"\r" and robot.version == version \
                and robot.versioned(req):
            answers, answers_read = self._answers, self._answers_read
            if len(answers) >= PARSE_CACHE_SIZE:
                answers.clear()
                answers_read.clear()
            answers[msg] = answers_read[msg + b"\n"] = (version, msg, line)

    def _work(self, conn: Connection, t: float, end: float) -> None:
        """Answer queued messages request by request until `end` (at least one step).

        A message of one request (or none) is one step; a longer one is answered a request
        per step across turns (`conn.ctx` holds it meanwhile). Everything is looked up once
        per turn: this loop runs for every message a client sends. The messages of one turn
        share its request context: one client, and a time that is at most a turn (2 ms) old.
        """
        robot = self.robot
        request, message, parse, now = robot.request, robot.message, self._parse, self._now
        queue, out, answers = conn.queue, conn.out, self._answers
        hook_in, hook_out = self.on_message_in, self.on_message_out
        turn = RequestContext(conn, t)
        while True:
            ctx = conn.ctx
            if ctx is not None:  # a message of several requests, one per step
                try:
                    part = request(ctx, conn.requests[conn.index])
                except Exception as exc:
                    # Whatever went wrong (a get property that raised), the message is owed
                    # one line: otherwise the client's lines slip out of step.
                    self._finish(conn, ctx, self._fault(conn, exc))
                else:
                    conn.index += 1
                    if part:
                        conn.answer.append(part)
                    if conn.index == len(conn.requests):
                        conn.answer.append(conn.tail)
                        self._finish(conn, ctx, b"".join(conn.answer))
            else:
                if not queue:
                    return
                msg = queue.popleft()
                ctx = turn
                if hook_in is not None:
                    hook_in(conn, t, msg)
                message(ctx)
                if isinstance(msg, TooLong):
                    line = self._too_long
                elif (kept := answers.get(msg)) is not None and kept[0] == robot.version:
                    line = kept[2]
                else:
                    requests, line = parse(msg)  # line: what ends the answer (an error or b"")
                    if len(requests) == 1:
                        version = robot.version
                        try:
                            answer = request(ctx, requests[0])
                        except Exception as exc:
                            line = self._fault(conn, exc)
                        else:
                            if not line:
                                self._keep(msg, requests[0], version, answer)
                            line = answer + line
                    elif requests:
                        conn.ctx, conn.requests, conn.index, conn.answer, conn.tail = (
                            RequestContext(conn, t), requests, 0, [], line)
                        continue
                out += line
                out += b"\n"
                if hook_out is not None:
                    hook_out(conn, t, line)
                if not queue:
                    return  # (the usual turn: one message, answered)
            t = now()
            if t >= end or conn.closed:
                return

    def _finish(self, conn: Connection, ctx: RequestContext, line: bytes) -> None:
        """The message's one response line."""
        conn.ctx, conn.requests, conn.answer = None, (), []
        if conn.closed:
            return
        conn.out += line
        conn.out += b"\n"
        if self.on_message_out is not None:
            self.on_message_out(conn, ctx.now, line)

    def answer_message(self, client: Client, msg: bytes | TooLong) -> bytes:
        """One message's whole answer line (with its `\\n`), all at once, as a turn of the
        server would write it: for tools and tests that have no socket."""
        ctx = RequestContext(client, self._now())
        self.robot.message(ctx)
        if isinstance(msg, TooLong):
            return self._too_long + b"\n"
        requests, tail = self._parse(msg)
        try:
            parts = [self.robot.request(ctx, req) for req in requests]
        except Exception as exc:
            return self._fault(client, exc) + b"\n"
        return b"".join(parts) + tail + b"\n"

    def _fault(self, client: Client, exc: Exception) -> bytes:
        log.error("could not answer a message from %s", client.peer, exc_info=exc)
        return format_response(error_response(
            "robot", "mcp", "fault", f"internal error {type(exc).__name__}")).encode("ascii")

    def _end_input(self, conn: Connection) -> None:
        """FIN from the client: it can command nothing more, but its answers are still owed.

        Closing at once would throw away unsent output (`printf 'robot:robot.get=()\\n' | nc`
        on a slow link); the socket closes when the output has drained.
        """
        conn.input_ended = True
        self.scheduler.remove_reader(conn.fd)
        if not conn.out:
            self._drop(conn, "closed by client")
            return
        self._report_lost(conn)
        self._flush(conn)

    def _flush(self, conn: Connection) -> None:
        if conn.closed:
            return
        out = conn.out
        if out and not conn.writing and not conn.input_ended:  # the usual case: it all goes
            try:
                n = conn.sock.send(out)
            except (BlockingIOError, InterruptedError, ssl.SSLWantReadError,
                    ssl.SSLWantWriteError):
                n = 0
            except OSError as exc:
                self._drop(conn, f"write error: {exc.strerror or exc}")
                return
            if n == len(out):
                out.clear()
                return
            del out[:n]
        while out:
            try:
                n = conn.sock.send(out)
            except (BlockingIOError, InterruptedError, ssl.SSLWantReadError,
                    ssl.SSLWantWriteError):
                break
            except OSError as exc:
                self._drop(conn, f"write error: {exc.strerror or exc}")
                return
            del out[:n]
        if len(out) > self.max_output:
            self._drop(conn, f"not reading its responses ({len(out)} bytes unsent)")
            return
        if out:
            if not conn.writing:
                conn.writing = True
                self.scheduler.add_writer(conn.fd, functools.partial(self._flush, conn))
        elif conn.input_ended:
            self._drop(conn, "closed by client")
        elif conn.writing:
            conn.writing = False
            self.scheduler.remove_writer(conn.fd)

    def _drop(self, conn: Connection, why: str, farewell: bytes = b"") -> None:
        if conn.closed:
            return
        conn.closed = True
        self.scheduler.remove_reader(conn.fd)
        self.scheduler.remove_writer(conn.fd)
        self.clients.pop(conn.fd, None)
        if farewell:
            with contextlib.suppress(OSError):
                conn.sock.send(farewell)
        try:
            conn.sock.close()
        except OSError as exc:  # pragma: no cover
            if exc.errno != errno.EBADF:
                raise
        log.info("client %s disconnected: %s", conn.peer, why)
        self._report_lost(conn)

    def _report_lost(self, conn: Connection) -> None:
        """Tell the robot layer once that this client can no longer command or feed."""
        if not conn.lost_reported:
            conn.lost_reported = True
            self.robot.client_lost(conn, self._now())


def _silence_key(client: Client) -> float:
    """Longest silent first (every server client is a Connection)."""
    return client.last_message_at if isinstance(client, Connection) else 0.0


def _say_and_close(sock: socket.socket, line: bytes) -> None:
    with contextlib.suppress(OSError):
        sock.setblocking(False)
        sock.send(line)
    sock.close()


def ensure_fd_limit(max_clients: int, buses: int) -> str | None:
    """Make sure this process may open the descriptors `max_clients` clients need: raise the
    soft RLIMIT_NOFILE up to the hard one if it must. None when it may; otherwise why not
    (an error for `server.max_clients`, checked before the supervisor starts)."""
    import resource

    needed = max_clients + FD_RESERVE + FD_PER_BUS * buses
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY or soft >= needed:
        return None
    if hard != resource.RLIM_INFINITY and hard < needed:
        return (f"{max_clients} clients need about {needed} file descriptors, and this process "
                f"may open at most {hard} (raise LimitNOFILE= in the service or `ulimit -n`, "
                "or lower max_clients)")
    try:
        resource.setrlimit(resource.RLIMIT_NOFILE, (needed, hard))
    except (ValueError, OSError) as exc:
        return f"cannot raise the file descriptor limit to {needed}: {exc}"
    log.info("file descriptor limit raised from %d to %d for %d clients", soft, needed,
             max_clients)
    return None
