"""The skid-steer drive trains of RAMP's own bases: SPEC 2.3's mix, rounded to the ints the
wheels take, on MARTE's four wheels (`BaseDrive`) or Scout's two (`round_half_away`).

Written against `ramp.api` alone, like the rest of RAMP's own modules.
"""

from __future__ import annotations

import math

from ramp.api import Motor, mix


def round_half_away(x: float) -> int:
    """Round to the nearest int, halves away from zero, so +s and -s mirror exactly."""
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


class BaseDrive:
    """Four wheels of a skid-steer base; front and back of a side always get the same value."""

    def __init__(self, lf: Motor, lb: Motor, rf: Motor, rb: Motor) -> None:
        self.lf, self.lb, self.rf, self.rb = lf, lb, rf, rb

    @property
    def wheels(self) -> tuple[Motor, Motor, Motor, Motor]:
        """In table 5.4 order: lf, lb, rf, rb."""
        return (self.lf, self.lb, self.rf, self.rb)

    def drive(self, speed: int, direction_deg: float) -> tuple[int, int]:
        """Command the mix; returns the (left, right) ints sent to the wheels."""
        left_f, right_f = mix(speed, direction_deg)
        left, right = round_half_away(left_f), round_half_away(right_f)
        self.lf.set_velocity(left)
        self.lb.set_velocity(left)
        self.rf.set_velocity(right)
        self.rb.set_velocity(right)
        return left, right

    def stop(self) -> None:
        for m in self.wheels:
            m.stop()

    def is_moving(self) -> bool:
        return any(m.velocity != 0 for m in self.wheels)
