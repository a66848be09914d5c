"""Latches that survive a restart (SPEC 2.2): the state file of latched faults and interlocks.

A lift that stalled on a rock, or a latched interlock, must not come back cleared because
the service restarted (a crash, a power cycle, `systemctl restart`) with nobody having looked
at it. So every latched device fault (`MODULE:DEVICE`, a `FaultLatch`) and every latched
interlock rule is kept in a small JSON file in the state directory, rewritten atomically
(a temporary file, fsync, rename) whenever a latch trips or is reset, and restored before the
buses open at the next start.

    {"format": 1, "config": "/etc/ramp/ramp.yaml",
     "devices": {"ble:lift": "lift stalled: moved 0.000 in 1.0 s ..."},
     "interlocks": ["bumper"]}

Where: `ramp run --state-dir DIR`, else systemd's `$STATE_DIRECTORY` (the unit's
`StateDirectory=ramp`), else `$XDG_STATE_HOME/ramp` (`~/.local/state/ramp`). One file per
robot config (its name carries a hash of the config's path), so MARTE and Scout run on one
laptop keep theirs apart.

A missing file is a first start (a warning says so, nothing is latched). A file that cannot
be read or parsed is a warning after which every latchable device and every latching rule
starts latched: safe, never cleared by accident. A latch named in the file that this config
no longer has (a module renamed) is a warning and is dropped. A state directory that cannot be
written costs persistence only (one warning; the latches still work in memory).
"""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ramp.common.state_files import write_atomic
from ramp.layers.functional.latch import FaultLatch

log = logging.getLogger("ramp.latches")

FORMAT = 1
#: Checks per second for a changed latch (each check compares two counters).
CHECK_HZ = 10.0
#: What a device restored from the file says while latched.
RESTORED = " (latched before the restart)"


def state_file(state_dir: Path, config_file: str) -> Path:
    """The config's state file in `state_dir`: `latches-NAME-HASH.json`."""
    resolved = str(Path(config_file).resolve())
    digest = hashlib.sha256(resolved.encode()).hexdigest()[:10]
    return state_dir / f"latches-{Path(config_file).stem}-{digest}.json"


class LatchState:
    """Reads the state file at start, writes it when a latch changes (a scheduler task)."""

    def __init__(self, path: Path, config_file: str = "") -> None:
        self.path = path
        self.config_file = config_file
        self._slots: Mapping[str, Any] = {}
        self._interlocks: Any = None
        self._seen = (-1, -1)
        self._saved: tuple[dict[str, str], list[str]] | None = None
        self._write_failed = False

    # -- start --------------------------------------------------------------------------------
    def restore(self, slots: Mapping[str, Any], interlocks: Any) -> None:
        """Latch what the file says was latched (everything, if it cannot be read)."""
        self._slots, self._interlocks = slots, interlocks
        devices, rules, problem = self._read()
        latches = self._latches()
        if problem:
            log.warning("latch state %s cannot be read (%s): every latchable device and "
                        "latching interlock starts latched; check the robot, then reset each "
                        "(MODULE:DEVICE.reset=(), robot:interlock.reset=(NAME))",
                        self.path, problem)
            why = f"latched at start: the latch state {self.path} could not be read"
            for latch in latches.values():
                latch.trip(why)
            interlocks.restore_latched([r.name for r in interlocks.rules if r.spec.latch])
        else:
            for label, reason in devices.items():
                latch = latches.get(label)
                if latch is None:
                    log.warning("latch state %s: %s was latched (%s) but this config has no "
                                "such latchable device: dropped", self.path, label, reason)
                    continue
                latch.trip(reason if reason.endswith(RESTORED) else reason + RESTORED)
            unknown = interlocks.restore_latched(rules)
            for name in unknown:
                log.warning("latch state %s: interlock %s was latched but this config has "
                            "no latching rule of that name: dropped", self.path, name)
        self._seen = (-1, -1)
        self.check(0.0, 0.0)

    def _read(self) -> tuple[dict[str, str], list[str], str]:
        """(devices, rule names, "") or ({}, [], why the file cannot be read)."""
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            log.warning("no latch state at %s: a first start here, nothing latched before "
                        "(it is kept there from now on)", self.path)
            return {}, [], ""
        except (OSError, UnicodeDecodeError) as exc:
            return {}, [], str(exc)
        try:
            data = json.loads(text)
        except ValueError as exc:
            return {}, [], f"not JSON: {exc}"
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            return {}, [], f"not a format-{FORMAT} latch state"
        devices, rules = data.get("devices"), data.get("interlocks")
        if not isinstance(devices, dict) or not all(
                isinstance(k, str) and isinstance(v, str) and v for k, v in devices.items()):
            return {}, [], "'devices' is not a mapping of MODULE:DEVICE to a reason"
        if not isinstance(rules, list) or not all(isinstance(r, str) for r in rules):
            return {}, [], "'interlocks' is not a list of rule names"
        return devices, rules, ""

    # -- running ------------------------------------------------------------------------------
    def _latches(self) -> dict[str, Any]:
        return {f"{name}:{device}": latch for name, slot in self._slots.items()
                for device, latch in getattr(slot.module, "latches", {}).items()}

    def check(self, now: float, dt: float) -> None:
        """The scheduler task: write the file when a latch tripped or was reset."""
        interlocks = self._interlocks
        seen = (FaultLatch.changes, interlocks.latch_changes if interlocks is not None else 0)
        if seen == self._seen:
            return
        self._seen = seen
        devices = {label: str(latch.reason) for label, latch in self._latches().items()
                   if latch.reason}
        rules = sorted(interlocks.latched_names()) if interlocks is not None else []
        if self._saved == (devices, rules):
            return
        if self._write(devices, rules):
            self._saved = (devices, rules)

    def _write(self, devices: dict[str, str], rules: list[str]) -> bool:
        data = {"format": FORMAT, "config": self.config_file, "devices": devices,
                "interlocks": rules}
        try:
            write_atomic(self.path, json.dumps(data, indent=1, sort_keys=True) + "\n")
        except OSError as exc:
            if not self._write_failed:
                log.warning("cannot keep the latch state in %s (%s): latches hold until "
                            "reset but will not survive a restart", self.path, exc)
            self._write_failed = True
            return False
        if self._write_failed:
            log.info("latch state kept in %s again", self.path)
        self._write_failed = False
        return True
