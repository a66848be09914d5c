"""BucketLadder: the excavator chain, driven by two motors that must always turn together
(one on each side of the belt), so it takes one velocity for both."""

from __future__ import annotations

from ramp.api import Motor


class BucketLadder:
    """Two chain motors, one velocity; wiring differences live in each Motor's polarity."""

    def __init__(self, left: Motor, right: Motor) -> None:
        self.left = left
        self.right = right

    @property
    def velocity(self) -> int:
        return self.left.velocity

    def vel(self, velocity: int) -> None:
        self.left.set_velocity(velocity)
        self.right.set_velocity(velocity)

    def stop(self) -> None:
        self.vel(0)

    def is_moving(self) -> bool:
        return self.left.velocity != 0 or self.right.velocity != 0
