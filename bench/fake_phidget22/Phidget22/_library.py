"""The library's own thread: attaches opened channels, then sends each one's samples at its
data interval, calling the handlers from this thread as libphidget22 does."""

from __future__ import annotations

import heapq
import threading
import time
from typing import Any

#: Steady readings: a 20.5 V rail through a 1135 sensor, a lift pot at mid stroke, an
#: empty bin's bridge ratio (V/V).
VOLTS = {0: 2.5 + 0.0681 * 20.5}
DEFAULT_VOLTS = 2.5
RATIO = 0.25e-3

_lock = threading.Lock()
_due: list[tuple[float, int, Any]] = []
_wake = threading.Event()
_started = False


def schedule(channel: Any, delay: float) -> None:
    global _started
    with _lock:
        heapq.heappush(_due, (time.monotonic() + delay, id(channel), channel))
        if not _started:
            _started = True
            threading.Thread(target=_run, name="phidget22-fake", daemon=True).start()
    _wake.set()


def _run() -> None:
    while True:
        with _lock:
            due = _due[0][0] if _due else None
        timeout = None if due is None else max(0.0, due - time.monotonic())
        _wake.wait(timeout)
        _wake.clear()
        now = time.monotonic()
        while True:
            with _lock:
                if not _due or _due[0][0] > now:
                    break
                _, _, channel = heapq.heappop(_due)
            again = channel._service()
            if again is not None:
                with _lock:
                    heapq.heappush(_due, (now + again, id(channel), channel))
