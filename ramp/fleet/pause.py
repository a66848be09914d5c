"""The fleet's pause, kept on disk so it survives agent, broker and robot restarts (SPEC 14).

`stopPause` writes it before anything else, `startPause` clears it; a file that cannot be
read counts as paused (fail safe: a fleet that paused a robot never loses that by a bad
disk), with a warning saying so. Writes are atomic (a temporary file renamed over the old).
The directory is `fleet.state_dir`, `--state-dir`, systemd's `$STATE_DIRECTORY`, or
`$XDG_STATE_HOME/ramp` (`~/.local/state/ramp`), as `ramp run`'s latch state.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from ramp.common.state_files import write_atomic

log = logging.getLogger("ramp.fleet.pause")


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
            write_atomic(self.path, json.dumps({"paused": paused, "reason": reason}))
        except OSError as exc:
            log.error("cannot record the fleet's pause in %s: %s", self.path, exc)
