"""Motor: the one place that knows how a motor is wired (polarity) and tuned (full duty,
deadband), so every component above can ask for "+50 % forward" and mean it."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ramp.hal.interfaces import MotorChannel
from ramp.schema import Block, Field

#: YAML keys of every motor device.
MOTOR_FIELDS = Block({
    "polarity": Field(int, 1, choices=(-1, 1), what="a motor polarity"),
    "full_duty": Field(float, 1.0, 0.0, 1.0, what="a duty for 100 %"),
    "deadband": Field(float, 0.0, 0.0, 0.5, what="a duty deadband"),
})


class Motor:
    """A velocity in % of full speed, turned into the controller's signed duty.

    `velocity` is what was last commanded (the number the operator asked for), even when the
    deadband sends it out as zero: it is what `get` reports. The duty it becomes is the
    channel's (`channel.duty`), and nothing below keeps another copy. The router has checked
    the velocity against the module's table, so it is trusted here: asserted, not clamped.
    """

    def __init__(self, channel: MotorChannel, polarity: int = 1, full_duty: float = 1.0,
                 deadband: float = 0.0) -> None:
        if polarity not in (-1, 1):
            raise ValueError(f"polarity must be -1 or 1, got {polarity!r}")
        self.channel = channel
        self.polarity = polarity
        self.full_duty = full_duty
        self.deadband = deadband
        self._velocity = 0

    @classmethod
    def from_params(cls, channel: MotorChannel, params: Mapping[str, Any]) -> Motor:
        """Build from a device's checked YAML keys (MOTOR_FIELDS)."""
        return cls(channel, int(params.get("polarity", 1)),
                   float(params.get("full_duty", 1.0)), float(params.get("deadband", 0.0)))

    @property
    def velocity(self) -> int:
        """The commanded velocity, % of full speed."""
        return self._velocity

    def duty_for(self, velocity: int) -> float:
        """The duty `velocity` % goes out as: polarity, full-duty scaling, deadband (within
        -1..1 by construction: |velocity| <= 100 and full_duty <= 1)."""
        duty = self.polarity * velocity / 100.0 * self.full_duty
        if abs(duty) < self.deadband:
            return 0.0
        return duty

    def set_velocity(self, velocity: int) -> None:
        """Command `velocity` % (-100..100, as validated above); the write does not block."""
        assert -100 <= velocity <= 100, f"{self.channel.label}: velocity {velocity} % unchecked"
        self._velocity = velocity
        self.channel.set_duty(self.duty_for(velocity))

    def stop(self) -> None:
        self.set_velocity(0)
