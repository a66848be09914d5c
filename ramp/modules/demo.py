"""A minimal module (one motor, one lamp) for trying the core without MARTE's hardware."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ramp.api import (
    Block,
    BoundDevice,
    DeviceSpec,
    FlagParam,
    Function,
    IntParam,
    Module,
    Property,
)


class DemoModule(Module):
    devices: ClassVar[dict[str, DeviceSpec]] = {
        "motor": DeviceSpec("motor", Block(), "any motor channel"),
        "lamp": DeviceSpec("digital_out", Block(), "any digital output"),
    }
    settings: ClassVar[dict[str, Block]] = {}

    def __init__(self, name: str, devices: Mapping[str, BoundDevice],
                 settings: Mapping[str, Mapping[str, Any]]) -> None:
        super().__init__(name)
        self.motor = devices["motor"].channel
        self.lamp = devices["lamp"].channel
        self.vel = 0
        self.add(Function("motor", "vel", (IntParam(-100, 100),), self._vel, "motion",
                          "motor velocity in %"))
        self.add(Function("lamp", "on", (FlagParam(),), self._lamp, "state", "lamp on/off"))
        self.prop(Property("motor", "vel", "int", lambda: self.vel, "%"))
        self.prop(Property("lamp", "on", "int", lambda: int(self.lamp.state)))

    def _vel(self, pct: int) -> None:
        self.motor.set_duty(pct / 100.0)
        self.vel = pct

    def _lamp(self, on: int) -> None:
        self.lamp.write(bool(on))

    def stop(self) -> None:
        self.vel = 0
        self.motor.set_duty(0.0)

    def is_moving(self) -> bool:
        return self.vel != 0
