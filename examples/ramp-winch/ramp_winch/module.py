"""The `winch` module: a rope wound by one motor, with a limit switch at the top.

MCP: `winch:rope.vel=(int -100..100)` (+ winds the rope up), `winch:winch.stop=()`,
`winch:winch.get=()` -> `winch:rope.vel=(int)`, `winch:top.press=(0|1)`. Winding up stops by
itself when the top switch closes.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ramp.api import (
    BUTTON_FIELDS,
    MOTOR_FIELDS,
    Button,
    DeviceSpec,
    DigitalInput,
    Function,
    IntParam,
    Module,
    Motor,
    MotorChannel,
    Property,
    Task,
)


class WinchModule(Module):
    """One motor winding a rope, one limit switch at the top."""

    # What the YAML wires: device name -> HAL channel kind, its own keys, a help text.
    devices: ClassVar[dict[str, DeviceSpec]] = {
        "motor": DeviceSpec("motor", MOTOR_FIELDS, "the winch motor; + winds up"),
        "top": DeviceSpec("digital_in", BUTTON_FIELDS, "limit switch, closed at the top"),
    }

    def __init__(self, name: str, devices: Mapping[str, Any],
                 settings: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        super().__init__(name)
        # `device` checks the channel's kind and the device's keys (polarity, debounce ...).
        self.motor = Motor.from_params(*self.device(devices, "motor", MotorChannel))
        self.top = Button.from_params(*self.device(devices, "top", DigitalInput))
        self.add(Function("rope", "vel", (IntParam(-100, 100),), self._vel, "motion",
                          "rope velocity in %; + winds up"))
        self.prop(Property("rope", "vel", "int", lambda: self.motor.velocity, "%"))
        self.prop(Property("top", "press", "int", lambda: int(self.top.pressed)))

    def _vel(self, pct: int) -> None:
        if pct > 0 and self.top.pressed:
            pct = 0  # already at the top: winding up would pull the rope out of its drum
        self.motor.set_velocity(pct)

    def stop(self) -> None:
        self.motor.stop()

    def is_moving(self) -> bool:
        return self.motor.velocity != 0

    def tasks(self) -> list[Task]:
        return [Task("limit", 100.0, self._limit)]

    def _limit(self, now: float, dt: float) -> None:
        self.top.tick(now)
        if self.top.pressed and self.motor.velocity > 0:
            self.motor.stop()
