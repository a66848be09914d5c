"""The simulated world as parts: a chassis, each payload, the floor or arena.

`ramp run --sim` builds one `World` per robot from the `ramp.emulators` entry points
(`ramp.simulation.backplane`): each module type's emulator (`module.TYPE`) is a *part* that
owns that module's signals (`module.device`, the YAML names) and its physics, and parts that
share state (a payload that needs the chassis' pose, two modules of one coupled model) reach
each other through `EmulatorContext.shared`. The world routes every signal to the first part
that knows it (a part raises KeyError for names it does not own); a signal no part knows is
simulated plainly (commands remembered, inputs read 0), so a new robot's wiring runs under
--sim before it has physics. `step(dt)` steps the parts in the order they were added, which
is the config's module order.

A part is any object with the methods of `ramp.hal.simio.SimWorld` it needs (`set_motor`,
`read_analog`, `read_digital`, `write_digital`, `read_bridge`, `set_servo`, `read_servo`),
`step(dt)`, and optionally `revision` (an int that moves on when its readings may change) and
`bus_present(bus)`, each one the part has when it is added.

A part whose `step` raises (a plugin's bug) is faulted on its own: its traceback logged once,
never stepped again, `on_part_fault` told (the backplane then makes its devices go dead on
their wires, so the backend's drivers fault those buses), and the other parts keep stepping.

The buses read a few signals and ask `revision` and `bus_present` on every tick, so a
signal's owner, once found, is called directly, and the parts with a `revision` or a
`bus_present` are listed when they are added.
"""

from __future__ import annotations

import logging
from typing import Any

log = logging.getLogger("ramp.sim")


class PlainSignals:
    """The signals no part owns: commands are remembered, inputs read zero."""

    def __init__(self) -> None:
        self.motors: dict[str, float] = {}
        self.outputs: dict[str, bool] = {}
        self.servos: dict[str, float] = {}

    def set_motor(self, name: str, duty: float) -> None:
        self.motors[name] = duty

    def read_analog(self, name: str) -> float:
        return 0.0

    def read_digital(self, name: str) -> bool:
        return False

    def write_digital(self, name: str, on: bool) -> None:
        self.outputs[name] = on

    def read_bridge(self, name: str) -> float:
        return 0.0

    def set_servo(self, name: str, target_deg: float | None, speed_dps: float) -> None:
        if target_deg is not None:
            self.servos[name] = target_deg  # an ideal servo: there at once

    def read_servo(self, name: str) -> float:
        return self.servos.get(name, 0.0)


class World:
    """Parts that own signals, stepped together; what the sim buses and emulators drive."""

    def __init__(self, parts: list[Any] | None = None) -> None:
        self.parts: list[Any] = []
        self.plain = PlainSignals()
        self._owner: dict[str, Any] = {}
        self._unplugged: set[str] = set()
        self._own_revision = 0
        self._revisioned: list[Any] = []  # the parts with a `revision` of their own
        self._bus_watchers: list[Any] = []  # the parts with a `bus_present` of their own
        #: Inputs the `sim` module holds at a value (`sim:input.set`): name -> quantity.
        self.overrides: dict[str, float] = {}
        #: Parts whose `step` raised, never stepped again (see the module docstring).
        self.faulted: list[Any] = []
        #: Told each part that faults, once (the backplane: its devices go dead).
        self.on_part_fault: Any = None
        for part in parts or []:
            self.add(part)

    def add(self, part: Any) -> None:
        """Add a part (once: a part shared by two modules is stepped once)."""
        if not any(p is part for p in self.parts):
            self.parts.append(part)
            if hasattr(part, "revision"):
                self._revisioned.append(part)
            if hasattr(part, "bus_present"):
                self._bus_watchers.append(part)

    def _route(self, method: str, name: str, *args: Any) -> Any:
        owner = self._owner.get(name)
        if owner is not None:
            return getattr(owner, method)(name, *args)
        for part in self.parts:
            fn = getattr(part, method, None)
            if fn is None:
                continue
            try:
                out = fn(name, *args)
            except KeyError:
                continue
            self._owner[name] = part
            return out
        self._owner[name] = self.plain
        log.info("sim: %s is not a signal of any physics part; it is simulated plainly "
                 "(commands recorded, inputs read 0)", name)
        return getattr(self.plain, method)(name, *args)

    # -- the SimWorld protocol (ramp.hal.simio) ---------------------------------------------
    # A signal's owner, once `_route` has found it, is called directly.
    def set_motor(self, name: str, duty: float) -> None:
        owner = self._owner.get(name)
        if owner is None:
            self._route("set_motor", name, duty)
        else:
            owner.set_motor(name, duty)

    def read_analog(self, name: str) -> float:
        if name in self.overrides:
            return float(self._overridden(name))
        owner = self._owner.get(name)
        if owner is None:
            return float(self._route("read_analog", name))
        return float(owner.read_analog(name))

    def read_digital(self, name: str) -> bool:
        if name in self.overrides:
            return bool(self._overridden(name))
        owner = self._owner.get(name)
        if owner is None:
            return bool(self._route("read_digital", name))
        return bool(owner.read_digital(name))

    def write_digital(self, name: str, on: bool) -> None:
        owner = self._owner.get(name)
        if owner is None:
            self._route("write_digital", name, on)
        else:
            owner.write_digital(name, on)

    def read_bridge(self, name: str) -> float:
        if name in self.overrides:
            return float(self._overridden(name))
        owner = self._owner.get(name)
        if owner is None:
            return float(self._route("read_bridge", name))
        return float(owner.read_bridge(name))

    def set_servo(self, name: str, target_deg: float | None, speed_dps: float) -> None:
        owner = self._owner.get(name)
        if owner is None:
            self._route("set_servo", name, target_deg, speed_dps)
        else:
            owner.set_servo(name, target_deg, speed_dps)

    def read_servo(self, name: str) -> float:
        owner = self._owner.get(name)
        if owner is None:
            return float(self._route("read_servo", name))
        return float(owner.read_servo(name))

    def bus_present(self, bus: str) -> bool:
        if bus in self._unplugged:
            return False
        for part in self._bus_watchers:  # noqa: SIM110 - a loop: all() over a generator is slower
            if not part.bus_present(bus):
                return False
        return True

    @property
    def revision(self) -> int:
        """Moves on whenever any part's readings may have changed."""
        total = self._own_revision
        for part in self._revisioned:
            total += int(part.revision)
        return total

    # -- the `sim` module's hooks (SPEC 12) -------------------------------------------------
    def set_input(self, name: str, quantity: float) -> None:
        """Input `name` reads as if it sensed `quantity` until `clear_input`."""
        self.overrides[name] = quantity
        self._own_revision += 1

    def clear_input(self, name: str) -> None:
        if self.overrides.pop(name, None) is not None:
            self._own_revision += 1

    def _overridden(self, name: str) -> float | bool:
        """An overridden input's reading: through its part's sensor model (`sensor_reading`:
        a battery's rail volts become pin volts) where the part has one, else the value."""
        quantity = self.overrides[name]
        for part in self.parts:
            reading = getattr(part, "sensor_reading", None)
            if reading is None:
                continue
            try:
                out: float | bool = reading(name, quantity)
            except KeyError:
                continue
            return out
        return quantity

    # -- controls ---------------------------------------------------------------------------
    def unplug(self, bus: str) -> None:
        """A bus's device vanishes (a pulled cable)."""
        self._unplugged.add(bus)
        self._own_revision += 1

    def replug(self, bus: str) -> None:
        self._unplugged.discard(bus)
        for p in self.parts:
            if hasattr(p, "replug"):
                p.replug(bus)
        self._own_revision += 1

    def step(self, dt: float) -> None:
        for part in self.parts:
            step = getattr(part, "step", None)
            if step is None:  # a payload its chassis carries is stepped by the chassis
                continue
            if self.faulted and any(p is part for p in self.faulted):
                continue
            try:
                step(dt)
            except Exception as exc:  # noqa: BLE001 - a part's bug faults that part only
                self._part_failed(part, exc)
        self._own_revision += 1  # a part with no revision of its own is sampled every step

    def _part_failed(self, part: Any, exc: Exception) -> None:
        """`part`'s step raised: it is faulted (never stepped again), said once with its
        traceback, and `on_part_fault` makes its devices go dead; the others keep going."""
        self.faulted.append(part)
        self._own_revision += 1
        log.error("sim: the emulator part %s raised in step; it is faulted (its devices go "
                  "dead on their wires), the other parts keep stepping",
                  type(part).__name__, exc_info=exc)
        if self.on_part_fault is not None:
            try:
                self.on_part_fault(part)
            except Exception:  # noqa: BLE001 - the report must not stop the other parts
                log.exception("sim: making the faulted part's devices go dead failed")
