"""A differential base (Scout, SPEC 10): two driven wheels, two bumpers, a battery monitor.

`base:base.drive=(speed,direction)` is MARTE's (SPEC 2.3's mix, one motor per side instead
of two), so teleop profiles and the autonomy's drive code work on either robot. Get rows:
`left_wheel.vel`, `right_wheel.vel`, `bumper_left.press`, `bumper_right.press`,
`battery.volt`. Settings block `battery_filter` as MARTE's base.

Written against `ramp.api` alone, as a plugin's module would be.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ramp.api import (
    BATTERY_FIELDS,
    BUTTON_FIELDS,
    FILTER_FIELDS,
    MOTOR_FIELDS,
    AnalogInput,
    Block,
    Button,
    DeviceSpec,
    DigitalInput,
    FloatParam,
    Function,
    IntParam,
    Module,
    Motor,
    MotorChannel,
    Property,
    SystemVoltage,
    Task,
    Voltage,
    mix,
)
from ramp.modules.skid_steer import round_half_away

WHEELS = ("left_wheel", "right_wheel")
BUMPERS = ("bumper_left", "bumper_right")


class DiffBaseModule(Module):
    """`base.drive`/`base.stop`, `vel` per wheel; bumpers and battery as get rows."""

    devices: ClassVar[dict[str, DeviceSpec]] = {
        "left_wheel": DeviceSpec("motor", MOTOR_FIELDS, "left drive motor"),
        "right_wheel": DeviceSpec("motor", MOTOR_FIELDS, "right drive motor"),
        "bumper_left": DeviceSpec("digital_in", BUTTON_FIELDS, "front-left bumper switch"),
        "bumper_right": DeviceSpec("digital_in", BUTTON_FIELDS, "front-right bumper switch"),
        "battery": DeviceSpec("analog_in", BATTERY_FIELDS, "battery voltage sensor"),
    }
    settings: ClassVar[dict[str, Block]] = {"battery_filter": FILTER_FIELDS}

    def __init__(self, name: str, devices: Mapping[str, Any],
                 settings: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        super().__init__(name)
        self.wheels = {w: Motor.from_params(*self.device(devices, w, MotorChannel))
                       for w in WHEELS}
        self.bumpers = {b: Button.from_params(*self.device(devices, b, DigitalInput))
                        for b in BUMPERS}
        self.voltage = SystemVoltage(
            Voltage.from_params(*self.device(devices, "battery", AnalogInput)),
            self.setting(settings, "battery_filter")["time_constant"])

        speed = IntParam(-100, 100)
        self.add(Function(name, "drive", (speed, FloatParam()), self._drive, "motion",
                          "drive at a speed % in a direction in degrees"))
        for w in WHEELS:
            self.add(Function(w, "vel", (speed,), self.wheels[w].set_velocity, "motion",
                              "one wheel's velocity in %"))
        for w in WHEELS:
            self.prop(Property(w, "vel", "int", self._velocity_of(w)))
        for b in BUMPERS:
            self.prop(Property(b, "press", "int", self._pressed(b)))
        self.prop(Property("battery", "volt", "float", lambda: self.voltage.value, "V"))

    def _velocity_of(self, wheel: str) -> Any:
        return lambda: self.wheels[wheel].velocity

    def _pressed(self, bumper: str) -> Any:
        return lambda: int(self.bumpers[bumper].pressed)

    def _drive(self, speed: int, direction: float) -> None:
        left, right = mix(speed, direction)
        self.wheels["left_wheel"].set_velocity(round_half_away(left))
        self.wheels["right_wheel"].set_velocity(round_half_away(right))

    def stop(self) -> None:
        for m in self.wheels.values():
            m.stop()

    def is_moving(self) -> bool:
        return any(m.velocity != 0 for m in self.wheels.values())

    def tasks(self) -> list[Task]:
        """Bumpers at 100 Hz (their debounce needs it), the battery filter at 50 Hz."""
        return [Task("bumpers", 100.0, self._bumpers_tick),
                Task("battery", 50.0, self.voltage.tick)]

    def _bumpers_tick(self, now: float, dt: float) -> None:
        for b in self.bumpers.values():
            b.tick(now)
