"""A pseudo-terminal that stands in for a USB-serial adapter, with unplug and replug.

The driver opens `path` (a stable symlink) exactly as it would open `/dev/ttyUSB0`; the
emulator reads the master side. `unplug()` closes the master, which the driver sees the way
it sees a pulled USB cable (EIO on write, hang-up on read); `replug()` makes a new pty and
points the same symlink at it, so the driver's retry finds the device again. No threads:
whoever owns the emulator calls `read_available()` from its loop.
"""

from __future__ import annotations

import contextlib
import errno
import os
import tty
from pathlib import Path


class PtyLink:
    """One emulated serial adapter: `path` for the driver, `master_fd` for the device."""

    def __init__(self, name: str, directory: str | os.PathLike[str]) -> None:
        self.directory = Path(directory)
        self.name = name
        self.path = str(self.directory / name)
        self.master_fd = -1
        self._slave_fd = -1
        self.slave_name = ""
        self.replug()

    @property
    def plugged(self) -> bool:
        return self.master_fd >= 0

    def replug(self) -> None:
        """A fresh pty behind the same path (after `unplug`, or the first time)."""
        self._close_fds()
        master, slave = os.openpty()
        # Raw mode on the slave: no echo, no line editing, no \n -> \r\n (0x0A is a valid
        # data byte in a packet).
        tty.setraw(slave)
        os.set_blocking(master, False)
        self.master_fd, self._slave_fd = master, slave
        self.slave_name = os.ttyname(slave)
        # Keeping our own slave fd open means reads on the master do not fail with EIO
        # between the driver's close and reopen; it holds no lock the driver would hit.
        tmp = f"{self.path}.{os.getpid()}.tmp"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(self.slave_name, tmp)
        os.replace(tmp, self.path)  # atomic: the path is never missing during a replug

    def unplug(self) -> None:
        """Pull the cable: the master closes and the path disappears."""
        self._close_fds()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)

    def close(self) -> None:
        self.unplug()

    def read_available(self) -> bytes:
        """Everything the driver has written so far; b"" when nothing (or unplugged)."""
        if self.master_fd < 0:
            return b""
        chunks: list[bytes] = []
        while True:
            try:
                chunk = os.read(self.master_fd, 65536)
            except BlockingIOError:
                break
            except OSError as exc:
                if exc.errno == errno.EIO:  # no slave open: nothing to read
                    break
                raise
            if not chunk:
                break
            chunks.append(chunk)
        return b"".join(chunks)

    def write(self, data: bytes) -> int:
        """Bytes from the device to the driver (a Sabertooth never sends; other devices may)."""
        if self.master_fd < 0:
            return 0
        try:
            return os.write(self.master_fd, data)
        except BlockingIOError:
            return 0

    def fileno(self) -> int:
        """The master fd, so a loop can `select` on it."""
        return self.master_fd

    def _close_fds(self) -> None:
        for fd in (self.master_fd, self._slave_fd):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master_fd = self._slave_fd = -1

    def __enter__(self) -> PtyLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
