"""Server layer: non-blocking MCP over TCP, serviced by the scheduler between ticks.

One response line per request line, in order, per client. A client that stops reading is
cut off once its unsent output passes a bound, so it can never block the loop or grow memory;
a client that floods gets at most one read's worth of work per wake-up, so others keep their
turn.
"""

from __future__ import annotations

import errno
import functools
import logging
import socket
from collections.abc import Callable

from ramp.layers.robot import Client
from ramp.mcp.messages import Response
from ramp.mcp.protocol import LineSplitter, TooLong, format_responses
from ramp.scheduler import Scheduler

log = logging.getLogger("ramp.server")

READ_CHUNK = 65536


class Connection(Client):
    """One TCP client: its socket, input splitter and pending output."""

    def __init__(self, sock: socket.socket, peer: str, max_line: int) -> None:
        super().__init__(peer)
        self.sock = sock
        self.fd = sock.fileno()
        self.splitter = LineSplitter(max_line)
        self.out = bytearray()
        self.closed = False


Handler = Callable[[Connection, "bytes | TooLong"], list[Response]]


class McpServer:
    """Accepts clients, splits their bytes into messages and writes the answers back."""

    def __init__(self, scheduler: Scheduler, handler: Handler,
                 on_disconnect: Callable[[Connection], None], host: str = "127.0.0.1",
                 port: int = 5577, max_clients: int = 8, max_line: int = 4096,
                 max_output: int = 1 << 20) -> None:
        self.scheduler = scheduler
        self.handler = handler
        self.on_disconnect = on_disconnect
        self.host = host
        self.port = port
        self.max_clients = max_clients
        self.max_line = max_line
        self.max_output = max_output
        self.clients: dict[int, Connection] = {}
        self.sock: socket.socket | None = None
        self.accepted = 0
        self.refused = 0

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
        sock.listen(64)
        sock.setblocking(False)
        self.sock = sock
        self.scheduler.add_reader(sock.fileno(), self._accept)

    def close(self) -> None:
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
                log.error("accept failed: %s", exc)
                return
            peer = f"{addr[0]}:{addr[1]}"
            if len(self.clients) >= self.max_clients:
                self.refused += 1
                log.warning("refused %s: already %d clients (server.max_clients)",
                            peer, len(self.clients))
                try:
                    sock.setblocking(False)
                    sock.send(b"robot:mcp.error=(busy,too many clients; at most "
                              + str(self.max_clients).encode() + b")\n")
                except OSError:
                    pass
                sock.close()
                continue
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn = Connection(sock, peer, self.max_line)
            self.clients[conn.fd] = conn
            self.accepted += 1
            self.scheduler.add_reader(conn.fd, functools.partial(self._readable, conn))
            log.info("client %s connected (%d of %d)", peer, len(self.clients),
                     self.max_clients)

    # -- reading and answering ----------------------------------------------------------------
    def _readable(self, conn: Connection) -> None:
        try:
            data = conn.sock.recv(READ_CHUNK)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._drop(conn, f"read error: {exc.strerror or exc}")
            return
        if not data:
            self._drop(conn, "closed by client")
            return
        for msg in conn.splitter.feed(data):
            responses = self.handler(conn, msg)
            if conn.closed:
                return
            conn.out += format_responses(responses)
        self._flush(conn)

    def _flush(self, conn: Connection) -> None:
        if conn.closed:
            return
        while conn.out:
            try:
                n = conn.sock.send(conn.out)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                self._drop(conn, f"write error: {exc.strerror or exc}")
                return
            del conn.out[:n]
        if len(conn.out) > self.max_output:
            self._drop(conn, f"not reading its responses ({len(conn.out)} bytes unsent)")
            return
        if conn.out:
            self.scheduler.add_writer(conn.fd, functools.partial(self._flush, conn))
        else:
            self.scheduler.remove_writer(conn.fd)

    def _drop(self, conn: Connection, why: str) -> None:
        if conn.closed:
            return
        conn.closed = True
        self.scheduler.remove_reader(conn.fd)
        self.scheduler.remove_writer(conn.fd)
        self.clients.pop(conn.fd, None)
        try:
            conn.sock.close()
        except OSError as exc:  # pragma: no cover
            if exc.errno != errno.EBADF:
                raise
        log.info("client %s disconnected: %s", conn.peer, why)
        self.on_disconnect(conn)
