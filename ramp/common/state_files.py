"""The state directory and its small files: what must survive a restart (latches, a fleet
pause), written so that a crash or a power cut leaves the old file or the new one, never a
mix (a temporary file in the same directory, fsync, rename, fsync of the directory)."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


def default_state_dir() -> Path:
    """systemd's `$STATE_DIRECTORY` (the first if several), else `$XDG_STATE_HOME/ramp`,
    else `~/.local/state/ramp`."""
    systemd = os.environ.get("STATE_DIRECTORY", "")
    if systemd:
        return Path(systemd.split(":")[0])
    xdg = os.environ.get("XDG_STATE_HOME", "")
    return (Path(xdg) if xdg else Path.home() / ".local" / "state") / "ramp"


def write_atomic(path: Path, text: str) -> None:
    """Replace `path` with `text` durably; raises OSError (the old file is then intact)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    with contextlib.suppress(OSError):  # the rename made durable (where a dir can be opened)
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
