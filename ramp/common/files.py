"""Opening an input file that must be a regular file, without ever waiting on it.

`open(path)` on a FIFO with no writer waits for ever, and a directory, `/dev/zero` or a
terminal on `/dev/stdin` reads forever or fails deep inside a parser. `open_regular` opens
non-blocking and checks the *open* descriptor (fstat), so what is checked is what is read,
and says in words what the path is instead (`it is a directory`, `it is a FIFO (pipe)`).
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path


class FileProblem(OSError):
    """A path that cannot be used as asked; str() is the reason in words."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason

    def __str__(self) -> str:
        return self.reason


class NotRegularFile(FileProblem):
    """The path cannot be read as a regular file."""


def open_regular(path: str | Path) -> tuple[int, int]:
    """(descriptor, size) of a regular file opened for reading; NotRegularFile otherwise.
    The caller closes the descriptor (`os.fdopen(fd, "rb")` does on close)."""
    if not str(path).strip():  # `--config ""` said only "cannot read: no such file"
        raise NotRegularFile("cannot read: the file name is empty")
    flags = os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise NotRegularFile(f"cannot read: {why(exc)}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise NotRegularFile(f"cannot read: {kind(info.st_mode)}; expected a regular file")
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd, info.st_size


def why(exc: OSError) -> str:
    """An OSError in a few words (`no such file`, `Permission denied`)."""
    if exc.errno == errno.ENOENT:
        return "no such file"
    return exc.strerror or str(exc)


def kind(mode: int) -> str:
    """What a non-regular file is, in words."""
    for test, what in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return f"it is {what}"
    return "it is not a regular file"
