"""mix: speed + direction -> left and right wheel velocities (SPEC 2.3).

Direction 0 is straight ahead, 90 spins clockwise, 180 is straight back. A skid-steer base
has no other degree of freedom, so one formula covers driving, pivoting and spinning. MARTE's
four-wheel drive train built on it is its module's own part (ramp/modules/skid_steer.py).
"""

from __future__ import annotations

import math


def mix(speed: float, direction_deg: float) -> tuple[float, float]:
    """Exact left and right velocities: s(cos d + sin d), s(cos d - sin d), scaled together
    so the larger magnitude equals |s|."""
    d = math.radians(math.fmod(direction_deg, 360.0))
    c, s = math.cos(d), math.sin(d)
    left, right = c + s, c - s
    biggest = max(abs(left), abs(right))  # = |cos| + |sin| >= 1, never zero
    return speed * left / biggest, speed * right / biggest
