"""RAMP's public API for plugin authors: everything a module, a driver or an emulator needs.

A package extends RAMP by registering classes under entry points (SPEC 10, `ramp.registry`):

- `ramp.modules`: a `Module` subclass. It declares its YAML devices (`devices`, each a
  `DeviceSpec` naming a HAL channel kind and its own keys as `Field`s), optional settings
  blocks (`settings`), and in `__init__` its MCP functions (`Function` with typed parameters:
  `IntParam`, `FloatParam`, `FlagParam`; a kind: motion, stop, state, read) and get rows
  (`Property`). It implements `stop()` and `is_moving()`, and may ask for periodic `Task`s.
  RAMP does the rest for it: config validation, `describe`, the watchdog, control
  arbitration, interlocks, the flight recorder, ramp-shell and the console.
- `ramp.drivers`: a `Bus` subclass (`driver_name`, `fields`, `channel_fields` per channel
  kind, and the `_open`/`_tick`/`_stop_motors`/`_close`/`_make_channel` hooks), handing out the
  HAL channels `MotorChannel`, `AnalogInput`, `DigitalInput`, `DigitalOutput`, `BridgeInput`,
  `ServoChannel`.
- `ramp.emulators`: `module.TYPE` -> `part(ctx, module_name, module_config)`, the physics of
  one module in the simulated world (an object with the `SimWorld` methods it owns, raising
  KeyError for signals that are not its own, and `step(dt)`); `bus.DRIVER` ->
  `emulated_bus(ctx, bus_config)`, which starts an emulator speaking DRIVER's wire protocol
  and returns the params the real driver opens it with. `ctx` is an `EmulatorContext`.

Only what this module exports is public; everything else in `ramp` may change without
notice. `API_VERSION` follows semantic versioning: a plugin may check the major number.
RAMP's own modules (`ramp.modules`) and emulators (`firmware_like`) import nothing else of
RAMP (tests/unit/test_api.py holds them to it), so this is all a module needs.

2.0 (from 1.1): MARTE's own parts left the API for MARTE's modules (`BaseDrive`,
`round_half_away`, `ThompsonActuator`, `LIFT_FIELDS`, `POT_FIELDS`, `BucketLadder`,
`VoltageDisplay`, `DISPLAY_FIELDS`); `RequestError` (refuse a request with a code and a
reason) and `EmulatorContext.add_pty_device` / `add_bus_emulator` joined it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol, TypeVar

from ramp.errors import ConfigError, DeviceError, RequestError
from ramp.hal.interfaces import (
    KINDS,
    AnalogInput,
    BridgeInput,
    Bus,
    DigitalInput,
    DigitalOutput,
    MotorChannel,
    ServoChannel,
)
from ramp.hal.simio import ServoWorld, SimWorld
from ramp.layers.functional import (
    BATTERY_FIELDS,
    BUTTON_FIELDS,
    FILTER_FIELDS,
    LOAD_CELL_FIELDS,
    MOTOR_FIELDS,
    Button,
    FaultLatch,
    Led,
    LoadCell,
    Motor,
    SystemVoltage,
    Voltage,
    mix,
)
from ramp.layers.functional.battery import Charge
from ramp.layers.module_distribution import (
    KINDS as FUNCTION_KINDS,
)
from ramp.layers.module_distribution import (
    BoundDevice,
    DeviceSpec,
    Function,
    Kind,
    Module,
    Property,
    Task,
)
from ramp.mcp.messages import Response, Value
from ramp.mcp.params import FlagParam, FloatParam, IntParam, Param
from ramp.schema import Block, Field, Rule

#: The version of this API (semantic versioning).
API_VERSION = "2.0"

#: HAL channel kinds a `DeviceSpec` may name (motor, analog_in, digital_in, digital_out,
#: bridge_in, servo).
CHANNEL_KINDS = KINDS

T = TypeVar("T")


class EmulatorContext(Protocol):
    """What `ramp run --sim` hands an emulator entry point."""

    #: The robot's checked config (`config.modules[NAME].devices[DEV].channel` ...).
    config: Any
    #: The simulated world every bus drives (signals named `module.device`).
    signals: Any
    #: A private directory for ptys and sockets, removed at the end.
    dir: Path

    def shared(self, key: str, make: Callable[[], T]) -> T:
        """One object per key for the whole world (a floor, a model two modules share)."""
        ...

    def add_device(self, device: Any) -> None:
        """`device.close()` is called when the simulation ends."""
        ...

    def add_service(self, service: Callable[[float], Any]) -> None:
        """`service(now)` runs at every tick, before the physics steps."""
        ...

    def motor_labels(self, bus: str, *keys: str) -> dict[Any, str]:
        """Channel key values -> `module.device` for the motors wired to `bus`."""
        ...

    def add_pty_device(self, bus: str, device: Any) -> None:
        """An emulated device behind a pty (RAMP's Sabertooth emulator is one): `device.link`
        is closed at the end, `device.service(now)` reads the driver's bytes as they arrive
        (the loop's wait watches the pty), `device.emulator.tick(now)` runs its timers, and
        the `sim` module can unplug it (`sim:BUS.unplug=()`)."""
        ...

    def add_bus_emulator(self, bus: str, emulator: Any) -> None:
        """Name the emulator behind `bus` (an object with `silence(bool)` lets the `sim`
        module unplug it; tests and benchmarks reach it by the bus's name)."""
        ...


__all__ = [
    # the contract
    "API_VERSION", "CHANNEL_KINDS", "FUNCTION_KINDS",
    # a module: its YAML devices and settings, its MCP table, its errors
    "Module", "DeviceSpec", "BoundDevice", "Function", "Property", "Task", "Kind",
    "Param", "IntParam", "FloatParam", "FlagParam", "Value", "Response",
    "Block", "Field", "Rule", "ConfigError", "DeviceError", "RequestError",
    # a driver and the HAL channels it hands out
    "Bus", "MotorChannel", "AnalogInput", "DigitalInput", "DigitalOutput", "BridgeInput",
    "ServoChannel",
    # an emulator
    "EmulatorContext", "SimWorld", "ServoWorld",
    # generic functional parts a module may build on
    "Motor", "MOTOR_FIELDS", "Button", "BUTTON_FIELDS", "Voltage", "SystemVoltage",
    "BATTERY_FIELDS", "FILTER_FIELDS", "Led", "LoadCell", "LOAD_CELL_FIELDS", "FaultLatch", "mix",
    # a battery\'s state of charge from its voltage (the robot\'s battery model in YAML)
    "Charge",
]
