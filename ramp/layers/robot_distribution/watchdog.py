"""The motion watchdog (SPEC 2.2), a `transitions` state machine: idle, armed, tripped.

**Every commander feeds for itself.** An accepted motion request makes its sender the
*commander* of each device it sets moving (replacing that device's previous commander; a
module-level function such as `base:base.drive` commands every device of its module) and arms
the watchdog, **before the module's code runs** (the robot layer calls `command` first, so a
plugin that raises half-way has still armed it). A zero-speed request is a stop: it forgets
the commanders of the devices it stops and never makes its sender a commander. While armed,
every client that commands a device of a module that is moving must keep sending complete
messages; each is judged by its own messages (`Client.last_heard`) against its own timeout
(`Client.timeout`, else the configured default). When any one of them is silent too long, or
disconnects, every module stops and the state reads `tripped` until the next accepted motion
request. So a monitoring client's polling, or a second client's unrelated motion request,
can never keep a silent or vanished client's motors running: there is no single "feeder"
whose place another client could take.

A stop that leaves nothing moving disarms it (`idle`); a stalled loop trips it too. The
commanders are forgotten whenever the watchdog leaves `armed`: from rest, only a new motion
request makes a commander again.

The states and their transitions are the table below. The hot paths (a message arriving,
the tick asking whether anyone is late) only read attributes; a transition (about 7 µs)
happens only when the state really changes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal

from transitions import Machine

from ramp.layers.robot_distribution.context import Client

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
    # A commander silent or lost while armed, a stalled loop: counted every time.
    {"trigger": "_trip", "source": "*", "dest": "tripped", "after": "_count_trip"},
    # A motion request armed it first, then was refused (nothing started): back as it was.
    {"trigger": "_back", "source": "armed", "dest": "tripped"},
]

#: Observer hook: (new state, why, clock time) after every change of state.
WatchdogHook = Callable[[str, str, float], None]


class Watchdog:
    state: State

    def __init__(self, timeout: float = 1.0) -> None:
        #: The default timeout (YAML `watchdog.timeout`) of a client that set none.
        self.timeout = timeout
        #: (module, device) -> the client whose accepted motion request it obeys; a
        #: module-level function is keyed (module, module) and stands for every device.
        self.commanders: dict[tuple[str, str], Client] = {}
        self.trips = 0
        #: Observer hook (the flight recorder): None costs nothing.
        self.on_change: WatchdogHook | None = None
        #: Called when a request arms it (the loop leaves its idle ticks). None: nothing.
        self.on_arm: Callable[[], None] | None = None
        self._why = ""
        self._machine = Machine(model=self, states=list(STATES), transitions=TRANSITIONS,
                                initial="idle", auto_transitions=False, queued=True,
                                after_state_change="_changed")

    def timeout_of(self, client: Client) -> float:
        """The client's own timeout, or the default."""
        own = client.timeout
        return self.timeout if own is None else own

    # -- from the robot layer -----------------------------------------------------------------
    def command(self, module: str, device: str, client: Client, now: float
                ) -> tuple[dict[tuple[str, str], Client], str]:
        """A motion request to `module:device` from `client` is about to run: it commands the
        device now (`device == module`: every device of the module) and the watchdog is
        armed, before any of the module's code runs. Returns what `undo` needs."""
        before = (dict(self.commanders), self.state)
        commanders = self.commanders
        if device == module:
            for key in [k for k in commanders if k[0] == module]:
                del commanders[key]
        commanders[(module, device)] = client
        if self.state != "armed":
            self._go(self._arm, "motion", now)
            if self.on_arm is not None:
                self.on_arm()
        return before

    def undo(self, before: tuple[dict[tuple[str, str], Client], str], now: float) -> None:
        """The request `command` armed for was refused before it started anything."""
        self.commanders = before[0]
        if self.state == "armed" and before[1] == "idle":
            self._go(self._disarm, "motion request refused", now)
        elif self.state == "armed" and before[1] == "tripped":
            self._go(self._back, "motion request refused", now)

    def stopped(self, module: str, device: str) -> None:
        """`module:device` was stopped by a request (a zero speed, the module's stop; the
        module's own name: all of it): nobody commands it any more."""
        commanders = self.commanders
        if not commanders:
            return
        if device == module:
            for key in [k for k in commanders if k[0] == module]:
                del commanders[key]
        else:
            commanders.pop((module, device), None)

    def settle(self, now: float, moving: bool) -> None:
        """After an accepted motion request: nothing moving is the end of whatever it was."""
        if not moving:
            self.commanders.clear()
            if self.state != "idle":
                self._go(self._reset, "motion request left nothing moving", now)

    def disarm(self, now: float = 0.0) -> None:
        """Nothing moves any more: nothing to guard."""
        self.commanders.clear()
        if self.state == "armed":
            self._go(self._disarm, "nothing moving", now)

    def late(self, now: float, moving: Callable[[str], bool]) -> tuple[str, Client] | None:
        """While armed: the first (module:device, commander) whose commander has been silent
        for its timeout while the module moves, else None. The caller stops and `trip`s.
        A device's motion is its module's (`is_moving` is what a module answers): a device
        stops being commanded when a request stops it."""
        if self.state != "armed":
            return None
        default = self.timeout
        for (module, device), client in self.commanders.items():
            own = client.timeout
            if now - client.last_heard >= (default if own is None else own) and moving(module):
                return (module if device == module else f"{module}:{device}"), client
        return None

    def trip(self, why: str = "stalled", now: float = 0.0) -> None:
        """Motion was stopped (a late or lost commander, a stalled loop): `tripped` until the
        next accepted motion request, whatever the state was."""
        self.commanders.clear()
        self._go(self._trip, why, now)

    def client_lost(self, client: Client, moving: Callable[[str], bool]) -> list[str]:
        """Forget a client that is gone; the moving modules it commanded (the caller stops
        everything and trips when there are any)."""
        mine = [key for key, c in self.commanders.items() if c is client]
        for key in mine:
            del self.commanders[key]
        return sorted({m if d == m else f"{m}:{d}" for m, d in mine if moving(m)})

    def commands_moving(self, client: Client, moving: Callable[[str], bool]) -> bool:
        """The client commands a device of a module that is moving: it must keep talking."""
        return any(c is client and moving(m) for (m, _), c in self.commanders.items())

    def count(self, moving: Callable[[str], bool]) -> int:
        """How many clients command a module that is moving (`robot:watchdog.commanders`)."""
        return len({id(c) for (m, _), c in self.commanders.items() if moving(m)})

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
    _back: Callable[[], bool]
    _now = 0.0
