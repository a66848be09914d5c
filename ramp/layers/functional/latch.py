"""FaultLatch: a device fault that stays until someone acknowledges it (SPEC 2.2).

A component that detects a fault it must not recover from by itself (a lift that stalls: it
may be jammed on a rock, or wired backwards) trips its latch and stops. The latch survives
every stop, watchdog trip, takeover and re-attach: a routine stop (the autonomy's, the
console's dead-man release) must never re-arm a jammed actuator with nobody having looked at
it. Only an explicit reset clears it; a module declares the latch
(`Module.latched`), which gives the device its `reset` request, a get row and the refusal of
its motion requests for free.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import ClassVar

log = logging.getLogger("ramp.fault")


class FaultLatch:
    """`reason` is "" while clear, else why it latched (the first reason is kept).

    `cause`, where the component can read it, says why the fault would still be there ("" when
    it is gone): `reset` is refused while it says something (SPEC 2.2)."""

    #: Every trip and clear of any latch counts here: the supervisor's latch state
    #: (`ramp.runtime.latch_state`) writes its file when the count moves.
    changes: ClassVar[int] = 0

    def __init__(self, label: str, cause: Callable[[], str] | None = None) -> None:
        self.label = label  # who latched, for the log: "ble:lift"
        self.reason = ""
        self.cause = cause

    @property
    def latched(self) -> bool:
        return bool(self.reason)

    def trip(self, reason: str) -> None:
        """Latch (the caller has stopped the device); a second trip keeps the first reason."""
        if not self.reason:
            self.reason = reason
            FaultLatch.changes += 1
            log.error("%s fault latched: %s; its motion is refused until %s.reset=()",
                      self.label, reason, self.label)

    def clear(self, by: str = "") -> None:
        """The fault was seen and acknowledged (`MODULE:DEVICE.reset=()`)."""
        if self.reason:
            log.warning("%s fault reset%s (was: %s)", self.label, f" by {by}" if by else "",
                        self.reason)
            FaultLatch.changes += 1
        self.reason = ""

    def still_there(self) -> str:
        """Why the fault is still there ("" when its cause reads clear or cannot be read
        by this component at all); a `cause` that raises counts as still there."""
        if self.cause is None:
            return ""
        try:
            return self.cause()
        except Exception as exc:  # noqa: BLE001 - plugin code: fail closed
            return f"its cause cannot be read, {type(exc).__name__}: {exc}"
