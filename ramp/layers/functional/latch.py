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

log = logging.getLogger("ramp.fault")


class FaultLatch:
    """`reason` is "" while clear, else why it latched (the first reason is kept)."""

    def __init__(self, label: str) -> None:
        self.label = label  # who latched, for the log: "ble:lift"
        self.reason = ""

    @property
    def latched(self) -> bool:
        return bool(self.reason)

    def trip(self, reason: str) -> None:
        """Latch (the caller has stopped the device); a second trip keeps the first reason."""
        if not self.reason:
            self.reason = reason
            log.error("%s fault latched: %s; its motion is refused until %s.reset=()",
                      self.label, reason, self.label)

    def clear(self, by: str = "") -> None:
        """The fault was seen and acknowledged (`MODULE:DEVICE.reset=()`)."""
        if self.reason:
            log.warning("%s fault reset%s (was: %s)", self.label, f" by {by}" if by else "",
                        self.reason)
        self.reason = ""
