"""Injectable clocks: wall time on the robot, stepped time in tests and simulation.

Control code never reads the wall clock or sleeps; it receives `now` from the scheduler,
which reads it from one of these.
"""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    """What the scheduler needs from a clock."""

    virtual: bool

    def now(self) -> float:
        """Seconds on a monotonic time line."""
        ...


class MonotonicClock:
    """The robot's clock: `time.monotonic`, never stepped by NTP."""

    virtual = False

    #: The C function itself, not a method around it: the loop reads the clock a few times
    #: for every request it answers.
    now = staticmethod(time.monotonic)


class VirtualClock:
    """A clock that moves only when told to, so runs are fast and repeatable."""

    virtual = True

    def __init__(self, start: float = 0.0) -> None:
        self._now = start

    def now(self) -> float:
        return self._now

    def advance(self, dt: float) -> None:
        if dt < 0:
            raise ValueError("a virtual clock never runs backwards")
        self._now += dt

    def set(self, t: float) -> None:
        if t < self._now:
            raise ValueError("a virtual clock never runs backwards")
        self._now = t
