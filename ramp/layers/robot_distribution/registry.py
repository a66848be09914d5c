"""The module registry: every module the robot knows, and whether it is usable now.

A module's attachment is a `transitions` state machine (SPEC 2.2, hot plug):

    detached --attach--> ok --fail--> fault --attach--> ok

A module starts `detached` and attaches once every bus it uses is ready (it starts from
rest). Entering `fault` is the one route of a device fault: the module's motion stops, the
log says why, and an observer hears of it; the rest of the robot keeps working. A module
whose buses are ready again re-attaches by itself.

**Plugin code is untrusted on the safety path** (SPEC 2.2). A module's motion is stopped on
entering `fault` by the bus layer writing zeros to the module's own motor channels (`zero`,
given by the builder), after its `stop()` is tried: a `stop` that raises, or does nothing,
never leaves a motor running. `plugin_bug` is the one route of a module's code raising where
safety depends on it (`is_moving`, `stop`, `start`, a task, a motion function): the module
goes to `fault` and is attached again after `RETRY_S`, as a bus is retried. Its traceback
is logged once per fault episode (one kind of bug per place, whatever its message says): an
episode ends once the module has run `QUIET_S` without one.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping
from typing import Any, Literal

from transitions import Machine

from ramp.layers.module_distribution import Module

log = logging.getLogger("ramp.supervisor")

ModuleState = Literal["ok", "fault", "detached"]

#: A module faulted by its own code is attached again no sooner than this (s).
RETRY_S = 1.0
#: A module that ran this long (s) without a bug ends its fault episode: the next bug logs
#: its traceback again.
QUIET_S = 30.0


def _nothing() -> None:
    """A module with no motor channels (or built outside `ramp.runtime.build`)."""

STATES: tuple[ModuleState, ...] = ("detached", "ok", "fault")
TRANSITIONS: list[Any] = [
    {"trigger": "attach", "source": ["detached", "fault"], "dest": "ok", "before": "_leaving"},
    # from `detached` only for a module whose plugin could not be built (ramp.runtime.build)
    {"trigger": "fail", "source": ["ok", "detached"], "dest": "fault"},
]

#: Observer hook: (module, new state, reason, clock time) after every change of state.
ModuleStateHook = Callable[[str, str, str, float], None]


class ModuleSlot:
    """A known module, the buses it uses, and its attachment state (see the module doc)."""

    state: ModuleState
    attach: Callable[..., bool]
    fail: Callable[..., bool]

    def __init__(self, name: str, module: Module, buses: tuple[str, ...] = ()) -> None:
        self.name = name
        self.module = module
        self.buses = buses
        self.reason = "not started"
        #: A module faulted by its own task's exception attaches again no sooner than this
        #: (retried like hot plug, not at once).
        self.retry_at = 0.0
        #: Its bugs already logged with a traceback in this fault episode: (where, exception
        #: type); see the module docstring.
        self.bugs: set[tuple[str, str]] = set()
        #: Clock time it last attached (a fault episode ends QUIET_S after).
        self.ok_since = 0.0
        #: Zeros on the module's own motor channels, written by the bus layer (set by the
        #: builder): how its motion is stopped whatever its own `stop` does.
        self.zero: Callable[[], None] = _nothing
        self._start_bug: Exception | None = None
        #: Who provides its module type (`ramp.registry.origin`), named when its code
        #: raises (set by the builder).
        self.plugin = ""
        #: Observer hook (the flight recorder): None costs nothing.
        self.on_change: ModuleStateHook | None = None
        self._machine = Machine(model=self, states=list(STATES), transitions=TRANSITIONS,
                                initial="detached", auto_transitions=False, queued=True,
                                after_state_change="_changed")

    def on_enter_ok(self, now: float, reason: str = "") -> None:
        """Attached: every bus it uses is ready; it starts from rest."""
        self.reason = ""
        self.retry_at = 0.0
        self.ok_since = now
        try:
            self.module.start(now)
        except Exception as exc:  # noqa: BLE001 - plugin code: faulted by the registry
            self._start_bug = exc
            return
        log.info("module %s %s", self.name,
                 "attached" if self._was == "detached" else "re-attached")

    def on_enter_fault(self, now: float, reason: str) -> None:
        """A bus it uses failed: stop its motion (never let a failing stop hide the fault)."""
        self.reason = reason
        try:
            self.module.stop()
        except Exception as exc:  # noqa: BLE001 - the zeros below stop it all the same
            log.debug("module %s: stop raised %s on entering fault", self.name, exc)
        self.zero()
        log.error("module %s fault: %s; its motion is stopped", self.name, reason)

    def plugin_bug(self, where: str, exc: Exception, now: float) -> None:
        """The module's code raised in `where` (see the module docstring): `fault`, motors
        zeroed on the wire, the traceback once per episode, attached again after RETRY_S."""
        key = (where.split(" ", 1)[0], type(exc).__name__)
        text = f"{where} raised {type(exc).__name__}: {exc}".rstrip(": ")
        if where == "start" and self.plugin:  # at attach: name the plugin, as at boot
            text = f"{text} in {self.plugin}"
        if key not in self.bugs:
            self.bugs.add(key)
            log.error("module %s (%s): %s; the module is faulted and retried every %.0f s, "
                      "the rest keep running", self.name, self.plugin or "no plugin", text,
                      RETRY_S, exc_info=exc)
        self.retry_at = max(self.retry_at, now + RETRY_S)
        if self.state == "ok":
            self.fail(now, text)
        else:
            self.reason = text
            self.zero()

    def quiet(self, now: float) -> None:
        """A fault episode is over once the module has run QUIET_S without a bug."""
        if self.bugs and self.state == "ok" and now - self.ok_since >= QUIET_S:
            self.bugs.clear()

    def _leaving(self, now: float, reason: str = "") -> None:
        self._was = self.state

    _was: str = "detached"

    def _changed(self, now: float, reason: str = "") -> None:
        if self.on_change is not None:
            self.on_change(self.name, self.state, self.reason, now)


class ModuleRegistry:
    """Every module by name, attached and faulted as the buses they use come and go."""

    def __init__(self, slots: Mapping[str, ModuleSlot]) -> None:
        self.slots = dict(slots)

    def update(self, now: float, ready: Callable[[str], bool],
               why: Callable[[str], str]) -> None:
        """Attach every module whose buses are all ready; fault every attached one that has
        lost one (`why(bus)` says what is wrong with a bus)."""
        for slot in self.slots.values():
            if slot.retry_at == math.inf:  # faulted for good: its reason stays
                continue
            down = [b for b in slot.buses if not ready(b)]
            if not down:
                if slot.state != "ok" and now >= slot.retry_at:
                    slot.attach(now)
                    bug, slot._start_bug = slot._start_bug, None
                    if bug is not None:
                        slot.plugin_bug("start", bug, now)
                continue
            reason = "; ".join(f"bus {b}: {why(b)}" for b in down)
            if slot.state == "ok":
                slot.fail(now, reason)
            else:
                slot.reason = reason

    def attached(self) -> list[str]:
        return [name for name, slot in self.slots.items() if slot.state == "ok"]
