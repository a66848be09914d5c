"""Stalls and freezes (SPEC 2.2): stop every motor when the tick loop loses time.

Two halves, one per case:

- **The loop resumed.** The scheduler notices, before its next unit of work, that more than
  `stall_limit` has passed since the last tick (a stuck task, a blocked call, the process
  stopped by SIGSTOP or a debugger, a clock jump) and calls the supervisor's stall handler
  before anything else can reach a wire. `loop_stalled` then logs the event once, with the
  gap's length and where the time went.
- **The loop is stuck and still stuck.** The loop cannot notice anything, so this thread
  does: it only reads two numbers the scheduler publishes (when the loop last made progress
  and which unit of work is running) and, on a stall longer than `limit`, writes zeros
  through every driver that the loop is not inside (each bus has a lock; a bus the loop is
  stuck in is left to its controller's own timeout). It is the one place RAMP starts a
  thread for control work, and it must: a stuck thread cannot rescue itself. When the loop
  comes back, its own handler stops the modules and logs the event; the thread logs only if
  the loop is still stuck one more `limit` later, since then nothing else will.

The controllers' own serial timeout and systemd's watchdog restart are the other two layers.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ramp.runtime.supervisor import Supervisor

log = logging.getLogger("ramp.stall")

#: How long the guard waits for a bus the loop is using before leaving it alone.
BUS_LOCK_WAIT_S = 0.02


class StallGuard:
    def __init__(self, sup: Supervisor, limit: float = 0.25) -> None:
        self.sup = sup
        # A loop waiting out a long period is not stalled: never fire inside two periods.
        self.limit = max(limit, 2 * sup.scheduler.period)
        self.stalls = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()  # the fired-for bookkeeping, shared with the loop
        self._fired_for = 0.0  # the loop's alive mark the guard last fired for
        self._fired_at = 0.0
        self._fired_task = ""
        self._reported = True  # the last firing was logged (by the loop or by the thread)

    def start(self) -> None:
        if self.sup.clock.virtual:
            return  # virtual time has no stalls to guard
        self._thread = threading.Thread(target=self._watch, name="ramp-stall-guard", daemon=True)
        self._thread.start()

    @property
    def running(self) -> bool:
        """Whether the guard's thread is watching the loop."""
        return self._thread is not None and self._thread.is_alive()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None

    # -- the loop came back -------------------------------------------------------------------
    def loop_stalled(self, gap: float, unit: str) -> None:
        """The loop's own stall handler ran (every module stopped): log the event once."""
        with self._lock:
            guard_fired = not self._reported
            self._reported = True
        also = "; the stall guard had already sent zeros from its thread" if guard_fired else ""
        log.error("tick loop stalled for %.0f ms in %s: every module stopped before any other "
                  "output, watchdog tripped; motion resumes on a new motion request%s",
                  gap * 1e3, unit, also)

    # -- the loop is stuck --------------------------------------------------------------------
    def check(self, now_perf: float) -> bool:
        """One look at the loop; True when it fired. Public so tests can drive it."""
        sched = self.sup.scheduler
        alive = sched.alive_at
        if alive == 0.0 or now_perf - alive < self.limit:
            return False
        with self._lock:
            if self._fired_for == alive:
                if not self._reported and now_perf - self._fired_at >= self.limit:
                    self._reported = True
                    log.error("tick loop stuck for %.0f ms in %s and still stuck: the stall "
                              "guard sent zeros to every motor driver", (now_perf - alive) * 1e3,
                              self._fired_task)
                return False
            self._fired_for = alive
            self._fired_at = now_perf
            self._fired_task = sched.current_task or "(between tasks)"
            self._reported = False
            self.stalls += 1
        self.sup.stop_all_motors(alive, BUS_LOCK_WAIT_S)
        return True

    def _watch(self) -> None:
        period = max(self.limit / 4, 0.005)
        while not self._stop.wait(period):
            try:
                self.check(time.perf_counter())
            except Exception:  # noqa: BLE001 - the guard must never die
                log.exception("stall guard check failed")
