"""The pan/tilt gimbal: two Hitec HS-5645MG servos on a PhidgetAdvancedServo (thesis 5.28-5.32).

HAL-level emulator (USB cannot be emulated, SPEC 6.2): the `sim` gimbal driver gives it the
commands a Phidget22 `RCServo` channel would get and reads back what the channel would report.

Two things move, as on the real board:
- the controller's **position** (what Phidget22 reports: the pulse it is sending, in degrees)
  runs toward the target with the commanded velocity limit and acceleration (speed ramping),
  and fires "target reached" when it gets there;
- the servo's **horn** follows that position no faster than the servo can turn
  (`max_speed_dps`), so a velocity limit above the servo's real speed makes the horn lag.
  `angle_deg` is the horn: what the LIDAR ray-caster uses to place the scanner.

Positions stay inside the channel's limits (a target outside is refused, as Phidget22 refuses
one outside Min/MaxPosition). Engaging a channel makes the controller jump to its target (it
has no feedback); the horn then swings there at full servo speed. Time comes only from the
injected clock: `advance()` integrates up to `clock.now()`, exactly, in closed-form pieces.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

#: Hitec HS-5645MG: 0.23 s per 60 deg at 4.8 V (0.18 s at 6 V). ASSUMPTION: the
#: PhidgetAdvancedServo's servo supply on MARTE ran near 5 V, so the slower figure.
HS5645MG_SPEED_DPS = 60.0 / 0.23


class Clock(Protocol):
    def now(self) -> float: ...


class ServoEmulator:
    """One channel of the controller and the servo plugged into it."""

    def __init__(self, clock: Clock, *, min_deg: float, max_deg: float,
                 velocity_limit_dps: float = 90.0, acceleration_dps2: float = 720.0,
                 start_deg: float = 0.0, max_speed_dps: float = HS5645MG_SPEED_DPS) -> None:
        if not min_deg < max_deg:
            raise ValueError(f"servo limits {min_deg}..{max_deg} are empty")
        self.clock = clock
        self.min_deg = float(min_deg)
        self.max_deg = float(max_deg)
        self.max_speed_dps = float(max_speed_dps)
        self.velocity_limit_dps = 0.0
        self.acceleration_dps2 = 0.0
        self.set_velocity_limit(velocity_limit_dps)
        self.set_acceleration(acceleration_dps2)
        self.target_deg: float | None = None
        self.engaged = False
        self._x = min(self.max_deg, max(self.min_deg, float(start_deg)))  # controller position
        self._v = 0.0
        self.angle_deg = self._x  # the horn
        self._t = float(clock.now())
        self._reached: list[float] = []

    # -- the controller's commands ------------------------------------------------------------
    def set_target(self, deg: float) -> None:
        self.advance()
        if not math.isfinite(deg) or not self.min_deg <= deg <= self.max_deg:
            raise ValueError(f"target {deg} is outside {self.min_deg:g}..{self.max_deg:g}")
        self.target_deg = float(deg)
        if self.engaged and self._x == self.target_deg and self._v == 0.0:
            self._reached.append(self._x)

    def set_velocity_limit(self, dps: float) -> None:
        if not math.isfinite(dps) or dps <= 0.0:
            raise ValueError(f"velocity limit {dps} must be > 0")
        if hasattr(self, "_t"):
            self.advance()
        self.velocity_limit_dps = float(dps)

    def set_acceleration(self, dps2: float) -> None:
        if not math.isfinite(dps2) or dps2 <= 0.0:
            raise ValueError(f"acceleration {dps2} must be > 0")
        if hasattr(self, "_t"):
            self.advance()
        self.acceleration_dps2 = float(dps2)

    def set_engaged(self, on: bool) -> None:
        self.advance()
        on = bool(on)
        if on and not self.engaged:
            if self.target_deg is None:
                raise ValueError("engaging needs a target (the controller has no position)")
            self._x = self.target_deg  # no feedback: the pulse jumps to the target
            self._v = 0.0
            self._reached.append(self._x)
        self.engaged = on
        if not on:
            self._v = 0.0

    # -- what the controller reports, and the horn -------------------------------------------
    @property
    def position_deg(self) -> float | None:
        """The controller's position (its pulse), None while disengaged (Phidget22 cannot
        read it then)."""
        self.advance()
        return self._x if self.engaged else None

    @property
    def velocity_dps(self) -> float:
        self.advance()
        return self._v if self.engaged else 0.0

    @property
    def moving(self) -> bool:
        self.advance()
        return self.engaged and (self._v != 0.0 or self._x != self.target_deg)

    def angle_at(self) -> float:
        """The horn's angle now (advances to the clock first)."""
        self.advance()
        return self.angle_deg

    def take_reached(self) -> list[float]:
        """Positions at which "target reached" fired since the last call."""
        self.advance()
        out, self._reached = self._reached, []
        return out

    def reset(self) -> None:
        """Controller power-on: disengaged, no target, nothing pending; the horn stays."""
        self.advance()
        self.engaged = False
        self.target_deg = None
        self._v = 0.0
        self._reached = []

    # -- motion --------------------------------------------------------------------------------
    def advance(self) -> None:
        now = float(self.clock.now())
        h = now - self._t
        if h <= 0.0:
            return
        self._t = now
        x = self._x
        if x == self.angle_deg and self._v == 0.0 and (x == self.target_deg or not self.engaged):
            # At rest, the horn on the pulse: `_ramp` would not move and the horn would take
            # the pulse's value (the usual case between two of the leveller's moves).
            self.angle_deg = x
            return
        if self.engaged and self.target_deg is not None:
            was_there = self._x == self.target_deg and self._v == 0.0
            self._ramp(h)
            if not was_there and self._x == self.target_deg and self._v == 0.0:
                self._reached.append(self._x)
        # The horn chases the pulse at the servo's own speed.
        step = self.max_speed_dps * h
        gap = self._x - self.angle_deg
        self.angle_deg = self._x if abs(gap) <= step else self.angle_deg + math.copysign(step,
                                                                                          gap)

    def _ramp(self, h: float) -> None:
        """Move the controller position for `h` seconds toward the target: accelerate,
        cruise at the velocity limit, brake to land exactly on it (trapezoid, piecewise
        exact)."""
        assert self.target_deg is not None
        a = self.acceleration_dps2
        vmax = self.velocity_limit_dps
        for _ in range(8):  # at most four phases per call; a guard against float dithering
            if h <= 0.0:
                return
            d = self.target_deg - self._x
            v = self._v
            if d == 0.0 and v == 0.0:
                return
            direction = math.copysign(1.0, d) if d != 0.0 else -math.copysign(1.0, v)
            speed = v * direction  # along the way to the target
            if speed < 0.0 or speed > vmax + 1e-9:
                # Heading away, or too fast after a lower limit: brake toward 0 / vmax.
                goal = 0.0 if speed < 0.0 else vmax
                t_goal = abs(speed - goal) / a
                dt = min(h, t_goal)
                acc = -a * math.copysign(1.0, v)
                self._x += v * dt + 0.5 * acc * dt * dt
                self._v = direction * goal if dt == t_goal else v + acc * dt
                h -= dt
                continue
            dist = abs(d)
            brake = speed * speed / (2.0 * a)
            if brake >= dist * (1.0 - 1e-12) - 1e-12:
                # Brake now, exactly enough to stop on the target.
                dec = speed * speed / (2.0 * dist) if dist > 0.0 else a
                t_stop = speed / dec if dec > 0.0 else 0.0
                if h >= t_stop - 1e-9:  # within a nanosecond: there
                    self._x = self.target_deg
                    self._v = 0.0
                    return
                self._x += direction * (speed * h - 0.5 * dec * h * h)
                self._v = direction * (speed - dec * h)
                return
            if speed < vmax:
                # Accelerate until vmax or until braking must begin, whichever comes first.
                peak = math.sqrt((speed * speed + 2.0 * a * dist) / 2.0)
                top = min(vmax, peak)
                dt = min(h, (top - speed) / a)
                self._x += direction * (speed * dt + 0.5 * a * dt * dt)
                self._v = direction * (speed + a * dt)
                h -= dt
                continue
            # Cruise at vmax until the braking distance remains.
            cruise = dist - brake
            dt = min(h, cruise / vmax)
            self._x += direction * vmax * dt
            self._v = direction * vmax
            h -= dt


class PanTiltEmulator:
    """The gimbal: the pan and tilt channels of one controller board."""

    def __init__(self, clock: Clock, pan: ServoEmulator, tilt: ServoEmulator) -> None:
        self.clock = clock
        self.pan = pan
        self.tilt = tilt
        self.attached = True

    def angles(self) -> tuple[float, float]:
        """(pan, tilt) horn angles in degrees now: where the LIDAR really points."""
        return (self.pan.angle_at(), self.tilt.angle_at())

    def unplug(self) -> None:
        """USB lost: the board stops its pulses (servos go limp where they are)."""
        self.attached = False
        for s in (self.pan, self.tilt):
            s.reset()

    def plug(self) -> None:
        """USB back: the board starts from its power-on state; the driver re-sends all."""
        if not self.attached:
            self.attached = True
            for s in (self.pan, self.tilt):
                s.reset()


def gimbal_emulator(clock: Clock, gimbal: Any, *,
                    max_speed_dps: float = HS5645MG_SPEED_DPS) -> PanTiltEmulator:
    """A gimbal emulator shaped like an `autonomy.yaml` gimbal block: anything with `pan` and
    `tilt` having `min_deg`, `max_deg`, `velocity_dps`, `acceleration_dps2`."""

    def axis(cfg: Any) -> ServoEmulator:
        return ServoEmulator(clock, min_deg=cfg.min_deg, max_deg=cfg.max_deg,
                             velocity_limit_dps=getattr(cfg, "velocity_dps", 90.0),
                             acceleration_dps2=getattr(cfg, "acceleration_dps2", 720.0),
                             max_speed_dps=max_speed_dps)

    return PanTiltEmulator(clock, axis(gimbal.pan), axis(gimbal.tilt))
