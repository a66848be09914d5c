"""The autonomy's model of MARTE's base: footprint and skid-steer kinematics.

The autonomy needs a few numbers about the robot it drives: how big it is (to keep it off
rocks and walls) and how fast a `base:base.drive` percentage moves it (to turn a wanted
speed and turn rate into a command). They are copied here, not imported, because the
autonomy must not depend on the simulator: the numbers below are the same assumptions the
MARTE physics model makes, and their source is named on each line.

Sources: `firmware_like/marte_params.py` (the simulator's MARTE model; its own sources are the
thesis p.34 and the ASSUMPTIONS listed there) and SPEC 2.3 / 6.1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ramp.autonomy.arena import ROBOT_LENGTH_M, ROBOT_WIDTH_M


@dataclass(frozen=True)
class RobotModel:
    """Footprint and differential-drive kinematics of a skid-steer base.

    `yaw rate = skid_efficiency * (v_right - v_left) / track_width` (counter-clockwise
    positive, SPEC 6.1 frame); a wheel at 100 % runs at `wheel_free_speed_m_s`.
    """

    length_m: float = ROBOT_LENGTH_M  # SPEC 6.1: MARTE's footprint 1.2 m x 0.75 m
    width_m: float = ROBOT_WIDTH_M
    # marte_params.py: 4800 rpm motor free speed / 256:1 gearbox x pi x 12-inch wheel (0.3048 m)
    # = 0.299 m/s at the reference rail voltage (20 V); the rail runs 17-21 V, so the real
    # speed is within about -15 %..+5 % of this, which the closed-loop follower absorbs.
    wheel_free_speed_m_s: float = 4800.0 / 256.0 * math.pi * 0.3048 / 60.0
    track_width_m: float = 0.65  # marte_params.py track_width (ASSUMPTION there)
    skid_efficiency: float = 0.6  # marte_params.py skid_efficiency (ASSUMPTION there)

    @property
    def half_length_m(self) -> float:
        return 0.5 * self.length_m

    @property
    def half_width_m(self) -> float:
        return 0.5 * self.width_m

    @property
    def circumradius_m(self) -> float:
        """Radius of the disc a footprint sweeps when it spins in place about its centre."""
        return math.hypot(self.half_length_m, self.half_width_m)

    @property
    def max_yaw_rate_rad_s(self) -> float:
        """Spin rate at 100 % (left and right wheels at full speed in opposite senses)."""
        return self.skid_efficiency * 2.0 * self.wheel_free_speed_m_s / self.track_width_m

    def wheel_percents(self, v_m_s: float, yaw_rate_rad_s: float) -> tuple[float, float]:
        """(left %, right %) that give forward speed v and counter-clockwise yaw rate."""
        spread = yaw_rate_rad_s * self.track_width_m / (2.0 * self.skid_efficiency)
        scale = 100.0 / self.wheel_free_speed_m_s
        return (v_m_s - spread) * scale, (v_m_s + spread) * scale

    def body_velocity(self, left_pct: float, right_pct: float) -> tuple[float, float]:
        """(forward m/s, counter-clockwise rad/s) from wheel percentages: the inverse."""
        v_left = left_pct / 100.0 * self.wheel_free_speed_m_s
        v_right = right_pct / 100.0 * self.wheel_free_speed_m_s
        return (0.5 * (v_left + v_right),
                self.skid_efficiency * (v_right - v_left) / self.track_width_m)


MARTE = RobotModel()


def drive_command(left_pct: float, right_pct: float) -> tuple[float, float]:
    """(speed %, direction deg) for `base:base.drive` that yields these wheel percentages.

    SPEC 2.3 mixes left = s(cos d + sin d), right = s(cos d - sin d), scaled so the larger
    magnitude is |s|; so cos d and sin d are proportional to (L + R) and (L - R), and s is
    max(|L|, |R|). Direction 0 is ahead, 180 back, +90 spins clockwise.
    """
    speed = max(abs(left_pct), abs(right_pct))
    if speed == 0.0:
        return 0.0, 0.0
    return speed, math.degrees(math.atan2(left_pct - right_pct, left_pct + right_pct))


def wheel_mix(speed: float, direction_deg: float) -> tuple[float, float]:
    """SPEC 2.3's mix, for the autonomy's own checks and models: (left %, right %)."""
    d = math.radians(direction_deg)
    left, right = math.cos(d) + math.sin(d), math.cos(d) - math.sin(d)
    biggest = max(abs(left), abs(right))
    return speed * left / biggest, speed * right / biggest
