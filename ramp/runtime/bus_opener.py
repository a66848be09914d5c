"""Opening a device without holding the loop: each open runs on a short-lived thread.

This is an I/O edge, and why it needs a thread: opening a device can block in the kernel or
in a library for as long as it likes. pyserial's `socket://` handler connects with a 5 s
timeout, so a Sabertooth bus whose TCP peer never accepts held the loop 5 s on every retry
(the stall guard fired seven times in twelve seconds and stopped the unaffected BLE); a tty
open, a `tcdrain` on a USB adapter with flow control or a vendor library can hang too. The
thread only runs `bus.open()`; the loop waits for it a few milliseconds (a normal open is
done by then), and otherwise goes on and collects the result on a later tick. While an open
is in flight the bus is closed to everyone else: the loop never ticks, stops or commands it
(its modules are not attached), so no state is shared with the thread.

An open still running after `HANG_S` is reported once; the bus stays closed until the
thread returns (a thread cannot be killed), and its modules stay detached while the rest of
the robot works. On a virtual clock opens run inline, so simulated runs stay repeatable.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field

from ramp.errors import DeviceError
from ramp.hal.interfaces import Bus
from ramp.registry import origin

log = logging.getLogger("ramp.supervisor")

#: How long the loop waits for an open before going on (it collects it on a later tick).
WAIT_S = 0.005
#: An open running longer than this is reported as hanging.
HANG_S = 5.0


@dataclass
class _Attempt:
    bus: Bus
    started: float
    done: threading.Event = field(default_factory=threading.Event)
    error: DeviceError | None = None
    reported: bool = False
    cancelled: bool = False


class BusOpener:
    """Runs `bus.open(now)` off the loop; `poll` says how it went (None: still running)."""

    def __init__(self, inline: bool) -> None:
        self.inline = inline
        self._attempts: dict[str, _Attempt] = {}
        #: Driver bugs in `open` already logged with their traceback in this fault episode:
        #: (bus, exception type); the message may carry a counter or a time.
        self._bugs: set[tuple[str, str]] = set()

    def busy(self, name: str) -> bool:
        """An open of this bus is in flight: nobody else may touch the bus."""
        return name in self._attempts

    @property
    def in_flight(self) -> int:
        return len(self._attempts)

    def open(self, name: str, bus: Bus, now: float) -> DeviceError | None | bool:
        """Start opening (or look at the open in flight): None when it succeeded, the error
        when it failed, False while it is still running."""
        if self.inline:
            return _open(bus, now, self._bugs)
        attempt = self._attempts.get(name)
        if attempt is None:
            attempt = _Attempt(bus, now)
            self._attempts[name] = attempt
            threading.Thread(target=self._run, args=(attempt, now, self._bugs), daemon=True,
                             name=f"ramp-open-{name}").start()
            attempt.done.wait(WAIT_S)
        if not attempt.done.is_set():
            if not attempt.reported and now - attempt.started >= HANG_S:
                attempt.reported = True
                log.warning("bus %s (%s): opening has hung for %.1f s (the device does not "
                            "answer); its modules stay detached, the rest keep working",
                            name, bus.driver_name, now - attempt.started)
            return False
        del self._attempts[name]
        return attempt.error

    def forget(self, name: str) -> None:
        """Bus `name`'s fault episode is over: its next bug in `open` logs a traceback."""
        for key in [k for k in self._bugs if k[0] == name]:
            self._bugs.discard(key)

    def cancel_all(self) -> None:
        """Shutting down: an open that completes later closes its bus again."""
        for attempt in self._attempts.values():
            attempt.cancelled = True

    @staticmethod
    def _run(attempt: _Attempt, now: float, bugs: set[tuple[str, str]]) -> None:
        attempt.error = _open(attempt.bus, now, bugs)
        if attempt.cancelled and attempt.error is None:
            _close(attempt.bus)
        attempt.done.set()


def _open(bus: Bus, now: float, bugs: set[tuple[str, str]]) -> DeviceError | None:
    try:
        bus.open(now)
    except DeviceError as exc:
        _close(bus)
        return exc
    except Exception as exc:  # noqa: BLE001 - a driver bug must not kill the loop or thread
        key = (bus.name, type(exc).__name__)
        if key not in bugs:  # the traceback once per fault episode, not at every retry
            bugs.add(key)
            log.error("bus %s: the driver raised in open (%s); retrying every second, the "
                      "rest keep running", bus.name, origin("ramp.drivers", bus.driver_name),
                      exc_info=exc)
        _close(bus)
        return DeviceError(bus.name, f"open failed: {type(exc).__name__}: {exc} in "
                                     f"{origin('ramp.drivers', bus.driver_name)}")
    return None


def _close(bus: Bus) -> None:
    try:
        bus.close()
    except Exception:  # noqa: BLE001 - a closing bug must not hide why the open failed
        log.debug("bus %s: close after a failed open raised", bus.name, exc_info=True)
