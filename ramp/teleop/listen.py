"""The console's listening socket: out of file descriptors, it sheds newcomers and says so once.

With every descriptor in use (1,024 idle connections to the page's port were enough), the
event loop's `accept()` fails with EMFILE. asyncio (3.11) logs a traceback for it and keeps
trying in the same loop turn, then schedules one retry per failure, so the loop spent its
time printing tracebacks (182,118 in 17 s) and STOP from an open page took 0.6 s instead of
a few ms. Here the classic remedy: keep one spare descriptor; on EMFILE give it up, accept
the waiting connection and close it at once (the newcomer is refused, the queue drains),
then take the spare again. The condition is logged once, and its end with the count of
connections refused. Open pages, and their STOP, are not touched.

`raise_fd_limit` first lifts the soft descriptor limit to the hard one, so ordinary bursts
of connections never get there.
"""

from __future__ import annotations

import errno
import logging
import os
import resource
import socket

log = logging.getLogger("ramp.teleop")

_OUT_OF_FILES = (errno.EMFILE, errno.ENFILE)


def raise_fd_limit() -> int:
    """Soft RLIMIT_NOFILE up to the hard limit; returns the soft limit now in force."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard == resource.RLIM_INFINITY or hard > soft:
        target = hard if hard != resource.RLIM_INFINITY else max(soft, 65536)
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
        except (ValueError, OSError):
            pass
    return soft


class SheddingSocket(socket.socket):
    """A listening TCP socket whose `accept` refuses newcomers while descriptors run out."""

    def __init__(self, family: int = socket.AF_INET, type: int = socket.SOCK_STREAM) -> None:
        super().__init__(family, type)
        self._spare: int | None = _open_spare()
        self.shedding = False
        self.refused = 0

    def accept(self) -> tuple[socket.socket, object]:
        try:
            conn, addr = super().accept()
        except OSError as exc:
            if exc.errno not in _OUT_OF_FILES:
                raise
            self._shed()
            # To asyncio: nothing more to accept in this turn (no traceback, no retry storm).
            raise BlockingIOError(errno.EAGAIN, "connection refused: out of descriptors"
                                  ) from exc
        if self.shedding:
            self.shedding = False
            log.warning("accepting connections again (%d refused while out of file "
                        "descriptors)", self.refused)
        return conn, addr

    def _shed(self) -> None:
        if not self.shedding:
            self.shedding = True
            log.warning("out of file descriptors: refusing new connections to the console "
                        "until some close (open pages keep working)")
        if self._spare is not None:
            os.close(self._spare)
            self._spare = None
        try:
            conn, _ = super().accept()
        except OSError:
            pass
        else:
            conn.close()
            self.refused += 1
        self._spare = _open_spare()

    def close(self) -> None:
        if self._spare is not None:
            os.close(self._spare)
            self._spare = None
        super().close()


def _open_spare() -> int | None:
    try:
        return os.open(os.devnull, os.O_RDONLY)
    except OSError:
        return None


def listen(host: str, port: int) -> SheddingSocket:
    """A socket listening on (host, port), as `socket.create_server` would make it."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = SheddingSocket(family)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(socket.SOMAXCONN)
    except OSError:
        sock.close()
        raise
    return sock
