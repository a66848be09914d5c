"""Scout's chassis: a differential base on a flat floor (SPEC 10), a part of the sim world.

Two wheels driven through ODrive axes (the CAN emulator turns the commanded turns/s back into
a duty for `set_motor`), two front bumper switches, a battery. The floor is a walled room
(`FlatFloor`, shared through the emulator context so a payload could stand on it too); a
bumper closes while its front corner touches a wall, and the walls stop the robot.

Wiring as built (the YAML compensates with polarity, as on MARTE): positive duty rolls the
LEFT wheel forward and the RIGHT wheel backward (mirrored mounting).

Numbers are ASSUMPTIONS for a small indoor rover: 0.8 m/s at full duty, 0.1 s motor lag,
0.35 m track, 0.40 x 0.32 m footprint, a 3-cell lithium pack of 12.6 V full sagging
0.05 ohm under 2 A per wheel at full duty, in a 4 x 3 m room.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

FREE_SPEED_M_S = 0.8
MOTOR_TAU_S = 0.1
TRACK_M = 0.35
LENGTH_M = 0.40
WIDTH_M = 0.32
PACK_FULL_V = 12.6
PACK_R_OHM = 0.05
WHEEL_A = 2.0
IDLE_A = 0.5
#: Battery pack capacity (A s): 5 Ah.
PACK_AS = 5.0 * 3600.0
PACK_EMPTY_V = 9.9


@dataclass
class FlatFloor:
    """A level room with walls at x = 0, x = length, y = 0, y = width (m)."""

    length: float = 4.0
    width: float = 3.0


class DiffBaseChassis:
    """The chassis' pose, wheel speeds and battery; owns the signals `MODULE.DEVICE` of its
    module's wheels, bumpers and battery (any other name raises KeyError)."""

    def __init__(self, module: str, floor: FlatFloor, battery_offset: float = 2.5,
                 battery_scale: float = 0.0681) -> None:
        self.module = module
        self.floor = floor
        self.x, self.y, self.heading = floor.length / 2.0, floor.width / 2.0, 0.0
        self.duty = {"left_wheel": 0.0, "right_wheel": 0.0}
        self.speed = {"left_wheel": 0.0, "right_wheel": 0.0}  # fraction of free speed
        self.soc = 1.0
        self.volts = PACK_FULL_V
        self.battery_offset = battery_offset
        self.battery_scale = battery_scale
        self.time = 0.0
        self.revision = 0
        self._touch = {"bumper_left": False, "bumper_right": False}

    def _device(self, name: str, known: tuple[str, ...]) -> str:
        module, _, device = name.partition(".")
        if module != self.module or device not in known:
            raise KeyError(name)
        return device

    # -- signals ----------------------------------------------------------------------------
    def set_motor(self, name: str, duty: float) -> None:
        self.duty[self._device(name, ("left_wheel", "right_wheel"))] = max(-1.0, min(1.0, duty))

    def read_digital(self, name: str) -> bool:
        return self._touch[self._device(name, ("bumper_left", "bumper_right"))]

    def read_analog(self, name: str) -> float:
        self._device(name, ("battery",))
        return self.battery_offset + self.battery_scale * self.volts

    def sensor_reading(self, name: str, quantity: float) -> float | bool:
        """What input `name` reads when what it senses is `quantity` (the `sim` module's
        input override): a bumper pressed (non-zero) or not, the battery at `quantity` V."""
        device = self._device(name, ("bumper_left", "bumper_right", "battery"))
        if device == "battery":
            return self.battery_offset + self.battery_scale * quantity
        return quantity != 0

    def place(self, x: float, y: float, heading_deg: float) -> None:
        """Teleport (tests): the bumpers read what touches there."""
        self.x, self.y, self.heading = x, y, math.radians(heading_deg)
        self._contacts()
        self.revision += 1

    # -- physics ----------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        if dt <= 0.0:
            return
        alpha = 1.0 - math.exp(-dt / MOTOR_TAU_S)
        for w in self.speed:
            self.speed[w] += (self.duty[w] - self.speed[w]) * alpha
        left = self.speed["left_wheel"] * FREE_SPEED_M_S
        right = -self.speed["right_wheel"] * FREE_SPEED_M_S  # mirrored mounting
        v, yaw_rate = 0.5 * (left + right), (right - left) / TRACK_M
        mid = self.heading + 0.5 * yaw_rate * dt
        self.x += v * math.cos(mid) * dt
        self.y += v * math.sin(mid) * dt
        self.heading = math.remainder(self.heading + yaw_rate * dt, 2.0 * math.pi)
        self._contacts()
        amps = IDLE_A + WHEEL_A * sum(abs(d) for d in self.duty.values())
        self.soc = max(0.0, self.soc - amps * dt / PACK_AS)
        ocv = PACK_EMPTY_V + (PACK_FULL_V - PACK_EMPTY_V) * self.soc
        self.volts = ocv - amps * PACK_R_OHM
        self.time += dt
        self.revision += 1

    def _corners(self) -> list[tuple[float, float]]:
        c, s = math.cos(self.heading), math.sin(self.heading)
        hl, hw = LENGTH_M / 2.0, WIDTH_M / 2.0
        return [(self.x + f * c - lft * s, self.y + f * s + lft * c)
                for f, lft in ((hl, hw), (hl, -hw), (-hl, hw), (-hl, -hw))]

    def _contacts(self) -> None:
        """Walls stop the robot (pushed back inside); a front corner on a wall presses its
        bumper (front-left corner: left bumper)."""
        fl = self.floor
        xs = [p[0] for p in self._corners()]
        ys = [p[1] for p in self._corners()]
        self.x -= min(0.0, min(xs)) + max(0.0, max(xs) - fl.length)
        self.y -= min(0.0, min(ys)) + max(0.0, max(ys) - fl.width)
        eps = 1e-3
        front_left, front_right = self._corners()[:2]
        for bumper, (px, py) in (("bumper_left", front_left), ("bumper_right", front_right)):
            self._touch[bumper] = (px <= eps or px >= fl.length - eps or py <= eps
                                   or py >= fl.width - eps)


def diff_base_part(ctx: Any, module: str, config: Any) -> DiffBaseChassis:
    """`ramp.emulators` entry `module.diff_base`: the chassis on the world's flat floor."""
    floor = ctx.shared("floor", FlatFloor)
    battery = config.devices.get("battery")
    params = dict(battery.params) if battery is not None else {}
    return DiffBaseChassis(module, floor, float(params.get("offset", 2.5)),
                           float(params.get("scale", 0.0681)))
