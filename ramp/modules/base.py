"""MARTE's Base module: four-wheel skid-steer drive, docking buttons, battery monitor, LEDs.

Requests and get rows are exactly thesis tables 5.3 and 5.4 (SPEC 2.1). YAML settings blocks:

- `battery_filter`: `time_constant` (s, default 2.0) of the low-pass on `battery.volt`;
- `voltage_display`: the five thresholds, `blink_hz` and `hysteresis` of the three-LED battery
  display (sequence documented in ramp.modules.voltage_display).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
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
    DigitalOutput,
    FlagParam,
    FloatParam,
    Function,
    IntParam,
    Led,
    Module,
    Motor,
    MotorChannel,
    Property,
    SystemVoltage,
    Task,
    Value,
    Voltage,
)
from ramp.modules.skid_steer import BaseDrive
from ramp.modules.voltage_display import DISPLAY_FIELDS, VoltageDisplay

WHEELS = ("lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel")
DISPLAY_LEDS = ("led_high", "led_mid", "led_low")


class BaseModule(Module):
    """The Base: `drive`/`stop` for the whole drive train, `vel` per wheel, `user_led.on`."""

    devices: ClassVar[dict[str, DeviceSpec]] = {
        **{w: DeviceSpec("motor", MOTOR_FIELDS, f"{w[:2]} drive motor") for w in WHEELS},
        "battery": DeviceSpec("analog_in", BATTERY_FIELDS,
                              "power rail through a Phidget 1135 voltage sensor"),
        "l_button": DeviceSpec("digital_in", BUTTON_FIELDS, "left docking button"),
        "r_button": DeviceSpec("digital_in", BUTTON_FIELDS, "right docking button"),
        "user_led": DeviceSpec("digital_out", Block(), "general purpose LED"),
        "led_high": DeviceSpec("digital_out", Block(), "battery display, top LED"),
        "led_mid": DeviceSpec("digital_out", Block(), "battery display, middle LED"),
        "led_low": DeviceSpec("digital_out", Block(), "battery display, bottom LED"),
    }
    settings: ClassVar[dict[str, Block]] = {
        "battery_filter": FILTER_FIELDS,
        "voltage_display": DISPLAY_FIELDS,
    }

    def __init__(self, name: str, devices: Mapping[str, Any],
                 settings: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        super().__init__(name)
        motors = {w: Motor.from_params(*self.device(devices, w, MotorChannel)) for w in WHEELS}
        self.drive_train = BaseDrive(*(motors[w] for w in WHEELS))
        filt = self.setting(settings, "battery_filter")
        self.voltage = SystemVoltage(
            Voltage.from_params(*self.device(devices, "battery", AnalogInput)),
            filt["time_constant"])
        self.buttons = {b: Button.from_params(*self.device(devices, b, DigitalInput))
                        for b in ("l_button", "r_button")}
        self.user_led = Led(self.device(devices, "user_led", DigitalOutput)[0])
        high, mid, low = (Led(self.device(devices, n, DigitalOutput)[0]) for n in DISPLAY_LEDS)
        self.display = VoltageDisplay.from_settings(
            high, mid, low, self.setting(settings, "voltage_display"))

        speed = IntParam(-100, 100)
        self.add(Function(name, "drive", (speed, FloatParam()), self._drive,
                          "motion", "drive at a speed % in a direction in degrees"))
        for w in WHEELS:
            self.add(Function(w, "vel", (speed,), motors[w].set_velocity, "motion",
                              "one wheel's velocity in %"))
        self.add(Function("user_led", "on", (FlagParam(),), self._user_led, "state",
                          "user LED on or off"))

        for w in WHEELS:
            self.prop(Property(w, "vel", "int", _reader(motors[w])))
        for b in ("l_button", "r_button"):
            self.prop(Property(b, "press", "int", _pressed(self.buttons[b])))
        self.prop(Property("battery", "volt", "float", lambda: self.voltage.value, "V"))
        self.prop(Property("user_led", "on", "int", lambda: int(self.user_led.is_on)))

    # -- requests -----------------------------------------------------------------------------
    def _drive(self, speed: int, direction: float) -> None:
        self.drive_train.drive(speed, direction)

    def _user_led(self, on: int) -> None:
        self.user_led.set(bool(on))

    # -- lifecycle ----------------------------------------------------------------------------
    def stop(self) -> None:
        self.drive_train.stop()

    def is_moving(self) -> bool:
        return self.drive_train.is_moving()

    def tasks(self) -> list[Task]:
        """Buttons at 100 Hz (20 ms debounce needs the resolution), the battery filter at
        50 Hz, the LED display at 20 Hz (a 2 Hz blink needs far less)."""
        return [
            Task("buttons", 100.0, self._buttons_tick),
            Task("battery", 50.0, self.voltage.tick),
            Task("leds", 20.0, self._leds_tick),
        ]

    def _buttons_tick(self, now: float, dt: float) -> None:
        for b in self.buttons.values():
            b.tick(now)

    def _leds_tick(self, now: float, dt: float) -> None:
        self.display.tick(now, self.voltage.value)
        self.user_led.tick(now)


def _reader(m: Motor) -> Callable[[], Value]:
    return lambda: m.velocity


def _pressed(b: Button) -> Callable[[], Value]:
    return lambda: int(b.pressed)
