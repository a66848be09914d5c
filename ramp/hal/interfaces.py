"""The hardware interfaces the functional layer sees, and the bus every driver implements.

A `Bus` is one YAML `buses:` entry: a serial line with Sabertooths on it, a Phidget board,
a CAN interface. It hands out channel objects (motor, analog in, ...) at build time; the
channels keep working objects even while the bus is unplugged, so the layers above never
hold dangling references across a hot-plug.

Template pattern (as python-can's `BusABC`): public methods validate and record, drivers
implement the `_`-prefixed hooks. Nothing here blocks: reads return the newest sample the
bus's `tick` collected, writes are queued and flushed by `tick`.

Each bus has a lock, held by every public method that reaches its driver (open, tick, a
motor or output command, stop, close). Only one other thread ever takes it: the stall guard,
which writes zeros while the loop is stuck, and which must never do so while the loop is
inside the same pyserial object; it waits a moment for the lock and otherwise leaves that
bus to its controller's own timeout (`try_stop_motors`).
"""

from __future__ import annotations

import logging
import math
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from ramp.errors import ConfigError
from ramp.schema import Field

#: Channel kinds a bus may offer; YAML device entries name one through their module's schema.
KINDS = ("motor", "analog_in", "digital_in", "digital_out", "bridge_in")


class MotorChannel(ABC):
    """One motor output. Duty is signed, -1..1, as the controller sees it (no polarity)."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label
        self._duty = 0.0

    @property
    def duty(self) -> float:
        """The duty last commanded."""
        return self._duty

    def set_duty(self, duty: float) -> None:
        if not isinstance(duty, int | float) or not math.isfinite(duty):
            raise ValueError(f"{self.label}: duty must be a finite number, got {duty!r}")
        if not -1.0 <= duty <= 1.0:
            raise ValueError(f"{self.label}: duty {duty} is outside -1..1")
        bus = self.bus
        if bus is None:
            self._duty = float(duty)
            self._apply(self._duty)
            return
        if not bus.gate():
            return  # computed before a stall: the loop's stall handler stops this motor
        with bus.lock:
            self._duty = float(duty)
            self._apply(self._duty)

    @abstractmethod
    def _apply(self, duty: float) -> None:
        """Queue the duty for the wire; the bus's tick (or this call) sends it."""


class AnalogInput(ABC):
    """An ADC channel, in volts at the pin."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label

    @abstractmethod
    def read(self) -> float:
        """The newest sample, in volts."""


class DigitalInput(ABC):
    """A digital input; True when the line is active (a button pressed)."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label

    @abstractmethod
    def read(self) -> bool:
        """The newest state."""


class DigitalOutput(ABC):
    """A digital output (an LED)."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label
        self._state = False

    @property
    def state(self) -> bool:
        return self._state

    def write(self, on: bool) -> None:
        on = bool(on)
        if on != self._state:
            if self.bus is None:
                self._state = on
                self._apply(on)
                return
            with self.bus.lock:
                self._state = on
                self._apply(on)

    @abstractmethod
    def _apply(self, on: bool) -> None:
        """Drive the pin."""


class BridgeInput(ABC):
    """A Wheatstone bridge input (load cell), in mV/V."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label

    @abstractmethod
    def read(self) -> float:
        """The newest ratio, in mV/V."""


def _always() -> bool:
    return True


class Bus(ABC):
    """One physical link to controllers or I/O boards, built from a YAML `buses:` entry.

    Lifecycle: `open(now)` (raises DeviceError when the device is absent), then `tick(now, dt)`
    every base tick (raises DeviceError when it vanishes), `stop_motors()` to put zeros on the
    wire at once, `close()` (idempotent, best effort zeros first).
    """

    #: The name YAML uses in `driver:`.
    driver_name: ClassVar[str] = ""
    #: Bus-level YAML keys (besides `driver` and `sim`).
    fields: ClassVar[dict[str, Field]] = {}
    #: Per kind, the keys a device entry uses to pick a channel on this bus.
    channel_fields: ClassVar[dict[str, dict[str, Field]]] = {}

    def __init__(self, name: str, params: Mapping[str, Any]) -> None:
        self.name = name
        self.params = dict(params)
        self.is_open = False
        self.motors: list[MotorChannel] = []
        #: Asked before motion output; False means the loop has stalled and not yet stopped
        #: everything, so what is about to go out is stale. The supervisor sets it.
        self.gate: Callable[[], bool] = _always
        #: Held while the loop (or the stall guard) is inside the driver; see the docstring.
        self.lock = threading.RLock()

    def check_params(self, params: Mapping[str, Any]) -> dict[str, Any]:
        """This driver's keys of `params`, checked against `fields`, defaults filled in.

        The config loader has already checked them; this keeps a bus built directly (tests,
        tools) from accepting a bad value. Keys of other drivers are ignored, since the sim
        driver stands in for any of them. Raises ConfigError naming `buses.NAME.KEY`.
        """
        out: dict[str, Any] = {}
        for key, f in self.fields.items():
            try:
                if key in params:
                    out[key] = f.check(params[key])
                elif f.required:
                    raise ValueError(f"missing; expected {f.expected()}")
                else:
                    out[key] = f.default
            except ValueError as exc:
                raise ConfigError(str(exc), key=f"buses.{self.name}.{key}") from None
        return out

    # -- channels -----------------------------------------------------------------------------
    def channel(self, kind: str, label: str, spec: Mapping[str, Any]) -> Any:
        """Build the channel of `kind` chosen by `spec` (already checked against
        `channel_fields[kind]`)."""
        if kind not in self.channel_fields:
            raise ValueError(f"driver {self.driver_name} has no {kind} channels")
        ch = self._make_channel(kind, label, dict(spec))
        if isinstance(ch, MotorChannel):
            self.motors.append(ch)
        return ch

    @abstractmethod
    def _make_channel(self, kind: str, label: str, spec: dict[str, Any]) -> Any:
        """Driver hook: return the channel object."""

    # -- lifecycle ----------------------------------------------------------------------------
    def open(self, now: float) -> None:
        if self.is_open:
            return
        with self.lock:
            self._open(now)
            self.is_open = True

    def tick(self, now: float, dt: float) -> None:
        if self.is_open and self.gate():  # no refresh of a pre-stall value
            with self.lock:
                self._tick(now, dt)

    def stop_motors(self) -> None:
        """Command zero on every motor channel and push it to the wire now."""
        for m in self.motors:
            m._duty = 0.0
        if self.is_open:
            with self.lock:
                if self.is_open:
                    self._stop_motors()

    def try_stop_motors(self, wait: float) -> bool:
        """`stop_motors` from another thread (the stall guard): False, and nothing written,
        when the loop has been inside this bus's driver for longer than `wait`."""
        if not self.is_open:
            return True
        if not self.lock.acquire(timeout=wait):
            return False
        try:
            self.stop_motors()
        finally:
            self.lock.release()
        return True

    def close(self) -> None:
        if not self.is_open:
            return
        with self.lock:
            if not self.is_open:
                return
            try:
                self.stop_motors()
            except Exception as exc:  # noqa: BLE001 - closing must always finish
                logging.getLogger("ramp.hal").error(
                    "bus %s: could not stop motors on close: %s", self.name, exc)
            finally:
                self.is_open = False
                self._close()

    def ready(self) -> bool:
        """True once the device answers: open, and (for boards that attach asynchronously,
        like Phidgets) every channel attached. Modules attach only on ready buses."""
        return self.is_open

    def fileno(self) -> int | None:
        """A file descriptor the scheduler can wait on for input, or None."""
        return None

    def on_readable(self, now: float) -> None:  # noqa: B027 - optional hook, default no-op
        """Called by the scheduler when `fileno()` has input."""

    @abstractmethod
    def _open(self, now: float) -> None: ...

    @abstractmethod
    def _tick(self, now: float, dt: float) -> None: ...

    @abstractmethod
    def _stop_motors(self) -> None: ...

    @abstractmethod
    def _close(self) -> None: ...

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
