"""The hardware interfaces the functional layer sees, and the bus every driver implements.

A `Bus` is one YAML `buses:` entry: a serial line with Sabertooths on it, a Phidget board,
a CAN interface. It hands out channel objects (motor, analog in, ...) at build time; the
channels keep working objects even while the bus is unplugged, so the layers above never
hold dangling references across a hot-plug.

Template pattern (as python-can's `BusABC`): public methods check and record, drivers
implement the `_`-prefixed hooks. Nothing here blocks.

- **Commands.** A channel holds what it is commanded (`MotorChannel.duty`,
  `DigitalOutput.state`): that is the one copy of the value. It hands a new value to its bus
  through the bus's public `command_motor` / `command_output`, and the driver reads the
  channel when it sends (now, or at a refresh); drivers keep only what they have put on the
  wire. The layers above validated the value (the router checks every request against the
  module's table), so a channel only asserts the range, and never clamps. The bus itself
  sets its motors' duty to 0 when it opens (a device starts from rest) and when it stops them
  (`stop_motors`, `close`); within the loop that happens only together with a stop of the
  modules above, in the same unit of work (a stall, a fault, shutdown), so no layer ever
  reads a value the wire no longer carries.
- **Readings.** An input channel's `read()` returns the sample its bus's `tick` collected;
  readings change only inside a tick, which is what lets the layers above cache a `get`
  answer between ticks (see `ramp.layers.module_distribution`).
- **Faults.** A driver that meets an I/O error outside `tick` (in a command, in `drain`)
  records it in `failure`; `tick` raises it (or raises its own) as a `DeviceError` naming the
  bus. That is the one route by which a device fault reaches the layers above.

Each bus has a lock, held by every public method that reaches its driver (open, tick, a
motor or output command, drain, stop, close). Only one other thread ever takes it: the stall
guard, which writes zeros while the loop is stuck, and which must never do so while the loop
is inside the same pyserial object; it waits a moment for the lock and otherwise leaves that
bus to its controller's own timeout (`try_stop_motors`).
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from ramp.errors import ConfigError, DeviceError
from ramp.schema import Field, check_block

#: Channel kinds a bus may offer; YAML device entries name one through their module's schema.
KINDS = ("motor", "analog_in", "digital_in", "digital_out", "bridge_in", "servo")

#: Called with (channel label, value) for every command a bus hands to its driver.
CommandHook = Callable[[str, float], None]


#: A servo this close to its target (degrees) is where it was sent.
SERVO_AT_REST_DEG = 0.5


class MotorChannel:
    """One motor output. `duty` is signed, -1..1, as the controller sees it (no polarity)."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label
        #: The duty commanded now: the one copy, which the driver reads when it sends.
        self.duty = 0.0

    def set_duty(self, duty: float) -> None:
        """Command `duty`. The router validated the request it comes from, so a value out of
        -1..1 (or NaN) is a bug above: refused, never clamped."""
        if not -1.0 <= duty <= 1.0:
            raise ValueError(f"{self.label}: duty {duty!r} is outside -1..1")
        bus = self.bus
        if bus is None:
            self.duty = duty
            self._apply(duty)
            return
        bus.command_motor(self, duty)

    def _apply(self, duty: float) -> None:
        """A channel with no bus (a stand-in in a test) sees its new duty here."""


class AnalogInput(ABC):
    """An ADC channel, in volts at the pin."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label

    @abstractmethod
    def read(self) -> float:
        """The sample the bus's last tick collected, in volts (NaN before the first)."""


class DigitalInput(ABC):
    """A digital input; True when the line is active (a button pressed)."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label

    @abstractmethod
    def read(self) -> bool:
        """The state the bus's last tick collected."""


class DigitalOutput:
    """A digital output (an LED)."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label
        #: The state commanded now: the one copy, which the driver reads when it sends.
        self.state = False

    def write(self, on: bool) -> None:
        on = bool(on)
        if on == self.state:
            return
        bus = self.bus
        if bus is None:
            self.state = on
            self._apply(on)
            return
        bus.command_output(self, on)

    def _apply(self, on: bool) -> None:
        """A channel with no bus (a stand-in in a test) sees its new state here."""


class ServoChannel:
    """An RC servo: a target position in degrees, reached no faster than a speed limit.

    The controller (a Phidget RCServo board, an emulator) ramps the pulse toward the target at
    `speed_dps` and reports the position it is sending; RC servos have no other feedback.
    `target` is the one copy of the command, which the driver reads when it sends; `read()` is
    the position the bus's last tick collected (NaN before the first). A stop holds the servo
    where it is (its target becomes the position it reports): an arm that lets go falls."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label
        #: The position commanded now (degrees), None until the first command.
        self.target: float | None = None
        #: The speed limit of the move to `target`, degrees per second.
        self.speed_dps = 0.0
        #: The position the controller reported at the bus's last tick (NaN before one).
        self.position = float("nan")

    def move(self, deg: float, speed_dps: float) -> None:
        """Command a move to `deg` at `speed_dps`. The router validated the request; a value
        that is not finite or a speed <= 0 is a bug above: refused, never clamped."""
        if not (math.isfinite(deg) and math.isfinite(speed_dps) and speed_dps > 0.0):
            raise ValueError(f"{self.label}: move to {deg!r} at {speed_dps!r} deg/s")
        bus = self.bus
        if bus is None:
            self.target, self.speed_dps = deg, speed_dps
            return
        bus.command_servo(self, deg, speed_dps)

    def hold(self) -> None:
        """Stop where it is: the target becomes the reported position (nothing before one)."""
        if math.isfinite(self.position):
            self.move(self.position, self.speed_dps or 1.0)
        elif self.bus is not None:
            self.bus.command_servo(self, None, self.speed_dps)

    def read(self) -> float:
        return self.position


class BridgeInput(ABC):
    """A Wheatstone bridge input (load cell), in mV/V."""

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label

    @abstractmethod
    def read(self) -> float:
        """The ratio the bus's last tick collected, in mV/V (NaN before the first)."""


def _always() -> bool:
    return True


def _own(fields: Mapping[str, Field], values: Mapping[str, Any]) -> dict[str, Any]:
    """The keys of `values` that `fields` declares (see `Bus.check_params`)."""
    return {k: v for k, v in values.items() if k in fields}


class Bus(ABC):
    """One physical link to controllers or I/O boards, built from a YAML `buses:` entry.

    Lifecycle: `open(now)` (raises DeviceError when the device is absent), then `tick(now, dt)`
    every base tick (raises DeviceError when it vanishes), `stop_motors()` to put zeros on the
    wire at once, `close()` (idempotent, best effort zeros first).
    """

    #: The name YAML uses in `driver:`.
    driver_name: ClassVar[str] = ""
    #: Bus-level YAML keys (besides `driver` and `sim`).
    fields: ClassVar[Mapping[str, Field]] = {}
    #: Per kind, the keys a device entry uses to pick a channel on this bus.
    channel_fields: ClassVar[Mapping[str, Mapping[str, Field]]] = {}

    def __init__(self, name: str, params: Mapping[str, Any]) -> None:
        self.name = name
        self.params = dict(params)
        self.is_open = False
        self.motors: list[MotorChannel] = []
        self.outputs: list[DigitalOutput] = []
        self.servos: list[ServoChannel] = []
        #: Asked before motion output; False means the loop has stalled and not yet stopped
        #: everything, so what is about to go out is stale. The runtime sets it.
        self.gate: Callable[[], bool] = _always
        #: Held while the loop (or the stall guard) is inside the driver; see the docstring.
        self.lock = threading.RLock()
        #: An I/O error met outside `tick`, raised by the next `tick` (see the docstring).
        self.failure: DeviceError | None = None
        #: True while the loop waits on `fileno()` and calls `drain` when it is readable, so
        #: a driver need not poll its descriptor in `tick` (the runtime sets it).
        self.watched = False
        #: Observer hook: every command handed to the driver (label, duty or 0/1). None
        #: costs nothing; the runtime sets it for a recorder.
        self.on_command: CommandHook | None = None

    def check_params(self, params: Mapping[str, Any]) -> dict[str, Any]:
        """This driver's keys of `params`, checked against `fields`, defaults filled in: the
        one block check the config loader also runs (ConfigError naming `buses.NAME.KEY`).
        Other keys are left alone: the loader reports unknown keys, and the sim driver
        stands in for any driver, whose keys it keeps under `--sim`."""
        return check_block(self.fields, _own(self.fields, params), f"buses.{self.name}")

    # -- channels -----------------------------------------------------------------------------
    def channel(self, kind: str, label: str, spec: Mapping[str, Any]) -> Any:
        """Build the channel of `kind` chosen by `spec`, checked against
        `channel_fields[kind]` (the same check as the loader's)."""
        if kind not in self.channel_fields:
            raise ConfigError(f"driver {self.driver_name} has no {kind} channels", key=label)
        fields = self.channel_fields[kind]
        ch = self._make_channel(kind, label, check_block(fields, _own(fields, spec), label))
        if isinstance(ch, MotorChannel):
            self.motors.append(ch)
        elif isinstance(ch, DigitalOutput):
            self.outputs.append(ch)
        elif isinstance(ch, ServoChannel):
            self.servos.append(ch)
        return ch

    @abstractmethod
    def _make_channel(self, kind: str, label: str, spec: dict[str, Any]) -> Any:
        """Driver hook: return the channel object (`spec` is checked, defaults filled in)."""

    # -- commands (from this bus's channels) --------------------------------------------------
    def command_motor(self, ch: MotorChannel, duty: float) -> None:
        """A motor channel of this bus is commanded `duty`: record it on the channel and let
        the driver send it. Dropped while the loop has stalled and not yet stopped everything
        (`gate`): a value computed before the gap must never reach the wire."""
        if not self.gate():
            return
        with self.lock:
            ch.duty = duty
            if self.is_open:
                try:
                    self._motor_changed(ch)
                except Exception as exc:  # noqa: BLE001 - a driver bug: this bus's fault
                    self._driver_raised(exc, "a motor command")
        if self.on_command is not None:
            self.on_command(ch.label, duty)

    def command_output(self, ch: DigitalOutput, on: bool) -> None:
        """A digital output of this bus is switched: record it, let the driver send it."""
        with self.lock:
            ch.state = on
            if self.is_open:
                try:
                    self._output_changed(ch)
                except Exception as exc:  # noqa: BLE001 - a driver bug: this bus's fault
                    self._driver_raised(exc, "an output command")
        if self.on_command is not None:
            self.on_command(ch.label, float(on))

    def command_servo(self, ch: ServoChannel, deg: float | None, speed_dps: float) -> None:
        """A servo of this bus is sent to `deg` (None: no target, the servo is left where it
        is) at `speed_dps`: record it, let the driver send it. Gated like a motor."""
        if not self.gate():
            return
        with self.lock:
            ch.target, ch.speed_dps = deg, speed_dps
            if self.is_open:
                try:
                    self._servo_changed(ch)
                except Exception as exc:  # noqa: BLE001 - a driver bug: this bus's fault
                    self._driver_raised(exc, "a servo command")
        if self.on_command is not None and deg is not None:
            self.on_command(ch.label, deg)

    def _servo_changed(self, ch: ServoChannel) -> None:  # noqa: B027 - optional hook
        """Driver hook: `ch.target` or `ch.speed_dps` changed (bus open, lock held)."""

    def _driver_raised(self, exc: Exception, where: str) -> None:
        """A command hook raised (it should have set `failure`): the next `tick` faults the
        bus, as for an I/O error; the traceback is logged once per bus."""
        if self.failure is None:
            self.failure = exc if isinstance(exc, DeviceError) else DeviceError(
                self.name, f"driver error in {where}: {type(exc).__name__}: {exc}")
        if not isinstance(exc, DeviceError) and not self._bug_logged:
            self._bug_logged = True
            logging.getLogger("ramp.hal").error(
                "bus %s (%s): the driver raised on %s; the bus is faulted", self.name,
                self.driver_name, where, exc_info=exc)

    _bug_logged = False

    def _motor_changed(self, ch: MotorChannel) -> None:  # noqa: B027 - optional hook
        """Driver hook: `ch.duty` changed (bus open, lock held). Send it now or soon; an I/O
        error goes to `failure`, never out of here."""

    def _output_changed(self, ch: DigitalOutput) -> None:  # noqa: B027 - optional hook
        """Driver hook: `ch.state` changed (bus open, lock held); as `_motor_changed`."""

    # -- lifecycle ----------------------------------------------------------------------------
    def open(self, now: float) -> None:
        """Open the device; it starts from rest (zeros, whatever was asked while closed)."""
        if self.is_open:
            return
        with self.lock:
            self.failure = None
            for m in self.motors:
                m.duty = 0.0
            for sv in self.servos:
                sv.target, sv.position = None, math.nan
            self._open(now)
            self.is_open = True

    def tick(self, now: float, dt: float) -> None:
        """Collect readings, send what is due; raises DeviceError when the device failed."""
        if not self.is_open:
            return
        failure = self.failure
        if failure is not None:
            raise failure
        if self.gate():  # no refresh of a pre-stall value
            with self.lock:
                self._tick(now, dt)

    def drain(self, now: float) -> None:
        """The device has input (its `fileno()` is readable): read it now. An error is kept
        in `failure` for the next `tick`."""
        if self.is_open:
            with self.lock:
                self.on_readable(now)

    def stop_motors(self) -> None:
        """Command zero on every motor and put it on the wire now, whatever the pacing. The
        layers above are stopped in the same unit of work (the stall handler, a fault,
        shutdown); from the stall guard's thread, the loop's stall handler stops them before
        anything else goes out."""
        with self.lock:
            for m in self.motors:
                m.duty = 0.0
            for sv in self.servos:  # hold where it is
                sv.target = sv.position if math.isfinite(sv.position) else None
            if self.is_open:
                try:
                    self._stop_motors()
                except Exception:
                    # The driver's own stop raised (a bug, or the device failing): zeros
                    # through its command path, motor by motor, where it can still write;
                    # then the caller faults the bus, and its close ends the rest.
                    for m in self.motors:
                        with contextlib.suppress(Exception):  # the caller faults the bus
                            self._motor_changed(m)
                    raise

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

    def waiting(self) -> str:
        """Why an open bus is not ready yet, once that is worth telling the operator (a board
        that attaches asynchronously and is not plugged in); "" otherwise. The runtime logs
        it once and says "back" only when the bus becomes ready."""
        return ""

    def at_rest(self) -> bool:
        """Nothing on this bus moves or is about to: every motor at 0, every servo where it
        was sent, no command waiting to go out (`output_queued`). While every bus is at rest
        and no client commands motion, the loop ticks at `scheduler.idle_rate_hz`."""
        for m in self.motors:
            if m.duty:
                return False
        for sv in self.servos:
            if sv.target is not None and not abs(sv.target - sv.position) <= SERVO_AT_REST_DEG:
                return False
        return not self.output_queued()

    def output_queued(self) -> bool:
        """Driver hook: commands accepted and not yet on the wire (a paced link), which the
        bus's next ticks send."""
        return False

    def fileno(self) -> int | None:
        """A file descriptor the scheduler can wait on for input (or a hang-up), or None."""
        return None

    def on_readable(self, now: float) -> None:  # noqa: B027 - optional hook, default no-op
        """Driver hook for `drain` (lock held): the descriptor of `fileno()` is readable."""

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
