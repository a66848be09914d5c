"""The fleet's pause, kept on disk so it survives agent, broker and robot restarts (SPEC 14).

`stopPause` writes it before anything else, `startPause` clears it; a file that cannot be
read counts as paused (fail safe: a fleet that paused a robot never loses that by a bad
disk), with a warning saying so. Writes are atomic (a temporary file renamed over the old).
The directory is `fleet.state_dir`, `--state-dir`, systemd's `$STATE_DIRECTORY`, or
`~/.local/state/ramp`, as `ramp run`'s state file.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import tempfile
from pathlib import Path

log = logging.getLogger("ramp.fleet.pause")


def default_state_dir() -> Path:
    env = os.environ.get("STATE_DIRECTORY", "").split(":")[0]
    return Path(env) if env else Path.home() / ".local" / "state" / "ramp"


class PauseStore:
    """`paused` and the reason, in `DIR/fleet-SERIAL.json`."""

    def __init__(self, directory: Path, serial: str) -> None:
        self.path = directory / f"fleet-{serial}.json"
        self.paused = False
        self.reason = ""

    def load(self) -> bool:
        """Read the file (absent: not paused; unreadable: paused, with a warning)."""
        try:
            data = json.loads(self.path.read_text())
            self.paused = bool(data["paused"])
            self.reason = str(data.get("reason", ""))
        except FileNotFoundError:
            self.paused, self.reason = False, ""
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("%s cannot be read (%s): the robot stays paused until startPause",
                        self.path, exc)
            self.paused, self.reason = True, f"pause file unreadable: {exc}"
        return self.paused

    def set(self, paused: bool, reason: str = "") -> None:
        """Record the pause; an OSError is logged (the pause holds in memory regardless)."""
        self.paused, self.reason = paused, reason
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=self.path.parent, prefix=".fleet-", suffix=".tmp")
            with os.fdopen(fd, "w") as f:
                json.dump({"paused": paused, "reason": reason}, f)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
        except OSError as exc:
            log.error("cannot record the fleet's pause in %s: %s", self.path, exc)
            with contextlib.suppress(OSError, UnboundLocalError):
                os.unlink(tmp)
