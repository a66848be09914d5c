"""Last-resort guard: if the tick loop stalls, stop every motor driver directly.

This is the one place RAMP starts a thread, and it must: when a task blocks, the loop's
own thread cannot notice anything. The guard only reads two numbers the scheduler
publishes (when the loop last made progress and which task is running) and, on a stall
longer than `limit`, writes zeros through every driver once and logs the task's name.
The controllers' own serial timeout and systemd's watchdog restart are the other two layers.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ramp.supervisor import Supervisor

log = logging.getLogger("ramp.stall")


class StallGuard:
    def __init__(self, sup: Supervisor, limit: float = 0.25) -> None:
        self.sup = sup
        # A loop waiting out a long period is not stalled: never fire inside two periods.
        self.limit = max(limit, 2 * sup.scheduler.period)
        self.stalls = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._fired_for = 0.0

    def start(self) -> None:
        if self.sup.clock.virtual:
            return  # virtual time has no stalls to guard
        self._thread = threading.Thread(target=self._watch, name="ramp-stall-guard", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None

    def check(self, now_perf: float) -> bool:
        """One look at the loop; True when it fired. Public so tests can drive it."""
        sched = self.sup.scheduler
        alive = sched.alive_at
        if alive == 0.0 or now_perf - alive < self.limit or self._fired_for == alive:
            return False
        self._fired_for = alive
        self.stalls += 1
        task = sched.current_task or "(between tasks)"
        log.error("tick loop stalled %.0f ms in %s: stopping every motor driver directly",
                  (now_perf - alive) * 1e3, task)
        self.sup.stop_all_motors()
        return True

    def _watch(self) -> None:
        period = max(self.limit / 4, 0.005)
        while not self._stop.wait(period):
            try:
                self.check(time.perf_counter())
            except Exception:  # noqa: BLE001 - the guard must never die
                log.exception("stall guard check failed")
