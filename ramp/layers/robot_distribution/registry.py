"""The module registry: every module the robot knows, and whether it is usable now.

A module's attachment is a `transitions` state machine (SPEC 2.2, hot plug):

    detached --attach--> ok --fail--> fault --attach--> ok

A module starts `detached` and attaches once every bus it uses is ready (it starts from
rest). Entering `fault` is the one route of a device fault: the module's motion stops, the
log says why, and an observer hears of it; the rest of the robot keeps working. A module
whose buses are ready again re-attaches by itself.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import Any, Literal

from transitions import Machine

from ramp.layers.module_distribution import Module

log = logging.getLogger("ramp.supervisor")

ModuleState = Literal["ok", "fault", "detached"]

STATES: tuple[ModuleState, ...] = ("detached", "ok", "fault")
TRANSITIONS: list[Any] = [
    {"trigger": "attach", "source": ["detached", "fault"], "dest": "ok", "before": "_leaving"},
    {"trigger": "fail", "source": "ok", "dest": "fault"},
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
        #: Its task bugs already logged with a traceback: (task, exception type, message).
        self.bugs: set[tuple[str, str, str]] = set()
        #: Observer hook (the flight recorder): None costs nothing.
        self.on_change: ModuleStateHook | None = None
        self._machine = Machine(model=self, states=list(STATES), transitions=TRANSITIONS,
                                initial="detached", auto_transitions=False, queued=True,
                                after_state_change="_changed")

    def on_enter_ok(self, now: float, reason: str = "") -> None:
        """Attached: every bus it uses is ready; it starts from rest."""
        self.reason = ""
        self.retry_at = 0.0
        self.module.start(now)
        log.info("module %s %s", self.name,
                 "attached" if self._was == "detached" else "re-attached")

    def on_enter_fault(self, now: float, reason: str) -> None:
        """A bus it uses failed: stop its motion (never let a failing stop hide the fault)."""
        self.reason = reason
        try:
            self.module.stop()
        except Exception:
            log.exception("module %s failed to stop", self.name)
        log.error("module %s fault: %s; its motion is stopped", self.name, reason)

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
            down = [b for b in slot.buses if not ready(b)]
            if not down:
                if slot.state != "ok" and now >= slot.retry_at:
                    slot.attach(now)
                continue
            reason = "; ".join(f"bus {b}: {why(b)}" for b in down)
            if slot.state == "ok":
                slot.fail(now, reason)
            else:
                slot.reason = reason

    def attached(self) -> list[str]:
        return [name for name, slot in self.slots.items() if slot.state == "ok"]
