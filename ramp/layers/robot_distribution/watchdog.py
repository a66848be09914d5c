"""The motion watchdog (SPEC 2.2), a `transitions` state machine: idle, armed, tripped.

Armed by an accepted motion request, whose sender becomes the feeder; fed only by the
feeder's complete messages, so a monitoring client's polling never keeps a dead driver's
motors running; disarmed by a stop that leaves nothing moving; tripped on expiry, when the
feeder disconnects while armed, or when the loop stalled, until the next accepted motion
request.

The states and their transitions are the table below. The hot path (a message feeding it,
the tick asking whether it expired) only reads `state`; a transition (about 7 µs) happens
only when the state really changes: a motion request from the feeder of an armed watchdog
just renews it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal

from transitions import Machine

State = Literal["idle", "armed", "tripped"]

#: Shortest timeout accepted (s): a few ticks. Anything shorter trips between two messages of
#: a healthy client, and `1e-300` used to be accepted and shown as `0.0`.
MIN_TIMEOUT_S = 0.05
MAX_TIMEOUT_S = 60.0

STATES: tuple[State, ...] = ("idle", "armed", "tripped")
TRANSITIONS: list[Any] = [
    # An accepted motion request that leaves something moving (from armed: no transition).
    {"trigger": "_arm", "source": ["idle", "tripped"], "dest": "armed"},
    # A stop that leaves nothing moving: nothing to guard (a trip stays a trip).
    {"trigger": "_disarm", "source": "armed", "dest": "idle"},
    # An accepted motion request that leaves nothing moving: whatever it was, it is over.
    {"trigger": "_reset", "source": ["armed", "tripped"], "dest": "idle"},
    # Expiry, the feeder lost while armed, a stalled loop: counted every time.
    {"trigger": "_trip", "source": "*", "dest": "tripped", "after": "_count_trip"},
]

#: Observer hook: (new state, why, clock time) after every change of state.
WatchdogHook = Callable[[str, str, float], None]


class Watchdog:
    state: State

    def __init__(self, timeout: float = 1.0) -> None:
        self.timeout = timeout
        self.feeder: object | None = None
        self.last_feed = 0.0
        self.trips = 0
        #: Observer hook (the flight recorder): None costs nothing.
        self.on_change: WatchdogHook | None = None
        self._why = ""
        self._machine = Machine(model=self, states=list(STATES), transitions=TRANSITIONS,
                                initial="idle", auto_transitions=False, queued=True,
                                after_state_change="_changed")

    # -- from the robot layer -----------------------------------------------------------------
    def arm(self, client: object, now: float) -> None:
        """An accepted motion request left something moving: `client` feeds it from now."""
        self.feeder = client
        self.last_feed = now
        if self.state != "armed":
            self._go(self._arm, "motion", now)

    def disarm(self, now: float = 0.0) -> None:
        """Nothing moves any more: nothing to guard."""
        self.feeder = None
        if self.state == "armed":
            self._go(self._disarm, "nothing moving", now)

    def reset(self, now: float = 0.0) -> None:
        """An accepted motion request left nothing moving: idle, whatever it was (a trip is
        over once a new motion request is accepted)."""
        self.feeder = None
        if self.state != "idle":
            self._go(self._reset, "motion request left nothing moving", now)

    def feed(self, client: object, now: float) -> None:
        if self.state == "armed" and client is self.feeder:
            self.last_feed = now

    def expired(self, now: float) -> bool:
        """True once when the armed timer runs out (the caller stops everything)."""
        if self.state == "armed" and now - self.last_feed >= self.timeout:
            self._go(self._trip, "expired", now)
            return True
        return False

    def trip(self, why: str = "stalled", now: float = 0.0) -> None:
        """Motion was stopped under the robot (a stalled loop): `tripped` until the next
        accepted motion request, whatever the state was."""
        self._go(self._trip, why, now)

    def client_lost(self, client: object, now: float = 0.0) -> bool:
        """True when the lost client was feeding an armed watchdog (the caller stops)."""
        if self.state == "armed" and client is self.feeder:
            self._go(self._trip, "feeder lost", now)
            return True
        if client is self.feeder:
            self.feeder = None
        return False

    # -- the machine's callbacks --------------------------------------------------------------
    def _go(self, trigger: Callable[[], bool], why: str, now: float) -> None:
        self._why, self._now = why, now
        trigger()

    def _count_trip(self) -> None:
        self.trips += 1

    def _changed(self) -> None:
        if self.on_change is not None:
            self.on_change(self.state, self._why, self._now)

    # Triggers the machine adds to the model (declared for type checkers).
    _arm: Callable[[], bool]
    _disarm: Callable[[], bool]
    _reset: Callable[[], bool]
    _trip: Callable[[], bool]
    _now = 0.0
