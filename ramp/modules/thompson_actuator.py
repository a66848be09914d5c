"""ThompsonActuator: the BLE lift, a ball-screw linear actuator with a feedback pot.

The manufacturer allows only a DC drive, not a rapidly switched one (thesis 5.3.2.2), so
positioning is on-off: full speed toward the target or stop, never a proportional duty.
Two bands keep it from hunting:

- a move (`move_to`) drives until the position is within `hysteresis` of the target (the
  inner band), then stops; coasting stays well inside the outer band;
- while holding, it corrects only when the position leaves `tolerance` (the outer band,
  +-0.03 by default), and again drives back to the inner band.

Reversals always pass through at least one controller tick at rest. `extend`/`retract` run at
full speed to the end positions (>= 0.99 / <= 0.01); any mode, manual `vel` included, stops
there, so the end of the stroke is not a stall. A stall guard watches every driven period: if
the position does not progress by `stall_min_change` (scaled by the commanded speed) within
`stall_time`, the motor stops and a fault is latched (`latch`, a `FaultLatch`) until it is
reset (`clear_fault`, the module's `lift.reset=()`): no stop clears it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, Literal

from ramp.api import AnalogInput, Block, FaultLatch, Field, Motor, RequestError, Rule

#: YAML keys of the lift's feedback pot (required: every actuator's pot sits differently).
POT_FIELDS = Block({
    "volts_at_0": Field(float, lo=-50.0, hi=50.0, what="the pot voltage when fully retracted"),
    "volts_at_1": Field(float, lo=-50.0, hi=50.0, what="the pot voltage when fully extended"),
}, [Rule(lambda v: v["volts_at_0"] != v["volts_at_1"], "volts_at_0 and volts_at_1 must differ")])

#: Settings block `lift`.
LIFT_FIELDS = Block({
    "tolerance": Field(float, 0.03, 0.001, 0.5, what="a position tolerance"),
    "hysteresis": Field(float, 0.01, 0.0, 0.5, what="how close to its target a move stops"),
    "stall_time": Field(float, 1.5, 0.05, 60.0, what="a stall time in s"),
    "stall_min_change": Field(float, 0.01, 0.0, 0.5,
                              what="the least position change in stall_time at full speed"),
}, [Rule(lambda v: v["hysteresis"] < v["tolerance"],
         "lift hysteresis must be below its tolerance")])

END_LOW = 0.01
END_HIGH = 0.99
FULL = 100

Mode = Literal["idle", "manual", "extend", "retract", "hold"]


def _sign(x: float) -> int:
    return (x > 0) - (x < 0)


class ThompsonActuator:
    """Lift control: manual velocity, run to an end, or go to and hold a position."""

    def __init__(self, motor: Motor, pot: AnalogInput, volts_at_0: float, volts_at_1: float,
                 tolerance: float = 0.03, hysteresis: float = 0.01, stall_time: float = 1.5,
                 stall_min_change: float = 0.01) -> None:
        if volts_at_0 == volts_at_1:
            raise ValueError("volts_at_0 and volts_at_1 must differ")
        if not 0 <= hysteresis < tolerance:
            raise ValueError("lift hysteresis must be below its tolerance")
        self.motor = motor
        self.pot = pot
        self.volts_at_0 = volts_at_0
        self.volts_at_1 = volts_at_1
        self.tolerance = tolerance
        self.hysteresis = hysteresis
        self.stall_time = stall_time
        self.stall_min_change = stall_min_change
        self.mode: Mode = "idle"
        self.target: float | None = None
        #: The stall fault: latched by the stall guard, cleared only by a reset.
        self.latch = FaultLatch("lift", self._stall_cause)
        self._seeking = False  # a move_to still heading for the inner band
        self._ref_pos = 0.0
        self._ref_time: float | None = None  # stall guard reference; None = re-arm next tick

    @classmethod
    def from_params(cls, motor: Motor, pot: AnalogInput, pot_params: Mapping[str, Any],
                    settings: Mapping[str, Any]) -> ThompsonActuator:
        return cls(motor, pot, float(pot_params["volts_at_0"]), float(pot_params["volts_at_1"]),
                   float(settings["tolerance"]), float(settings["hysteresis"]),
                   float(settings["stall_time"]), float(settings["stall_min_change"]))

    # -- state --------------------------------------------------------------------------------
    @property
    def position(self) -> float:
        """0 retracted .. 1 extended, from the newest pot sample (not clamped: a reading past
        the ends says the calibration or the wiring is off)."""
        return (self.pot.read() - self.volts_at_0) / (self.volts_at_1 - self.volts_at_0)

    @property
    def velocity(self) -> int:
        """What the motor is commanded now, %: the controller's output during a move."""
        return self.motor.velocity

    @property
    def fault(self) -> str:
        """"" or the latched stall reason, "lift stalled: ..."."""
        return self.latch.reason

    @property
    def stalled(self) -> bool:
        return self.latch.latched

    def is_moving(self) -> bool:
        """Driven, or a move or hold in progress (a hold may drive at any moment)."""
        return self.mode != "idle" or self.motor.velocity != 0

    # -- commands -----------------------------------------------------------------------------
    def vel(self, velocity: int) -> None:
        """Manual drive at `velocity` %; stops by itself at the end it drives toward."""
        if velocity == 0:  # never refused: it only makes things safer
            self.mode, self.target = "idle", None
            self._drive(0)
            return
        self._refuse_if_faulted()
        self.mode, self.target = "manual", None
        self._drive(0 if self._at_end(velocity, self.position) else velocity)
        if self.motor.velocity == 0:
            self.mode = "idle"

    def extend(self) -> None:
        self._run_to_end(+1)

    def retract(self) -> None:
        self._run_to_end(-1)

    def move_to(self, target: float) -> None:
        """Go to `target` (0..1) and hold it."""
        assert 0.0 <= target <= 1.0, f"lift target {target} unchecked"
        self._refuse_if_faulted()
        self.mode, self.target, self._seeking = "hold", target, True
        pos = self.position
        out = self.motor.velocity
        if out != 0 and _sign(out) != _sign(self.target - pos):
            self._drive(0)  # reverse through rest; the next tick starts the move
            return
        if out != 0:
            self._drive(FULL * _sign(out))  # a manual crawl toward the target goes full speed
        self._hold_step(pos)

    def stop(self) -> None:
        """Motor to zero, any move cancelled. A latched stall stays latched: no stop, watchdog
        trip, takeover or re-attach may silently re-arm a jammed lift (`clear_fault`)."""
        self.mode, self.target, self._seeking = "idle", None, False
        self._drive(0)

    def _stall_cause(self) -> str:
        """What keeps a stall from being checked: a stall itself shows only while driving, but
        with no position reading the guard that caught it is blind (reset refused)."""
        if not math.isfinite(self.position):
            return "the lift's position cannot be read (lift_pot): the stall guard is blind"
        return ""

    def clear_fault(self) -> None:
        """The stall has been seen and acknowledged (the module's `lift.reset=()`)."""
        self.latch.clear()

    # -- control ------------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        pos = self.position
        if not math.isfinite(pos):  # no pot reading: no end stops, no positioning
            if self.motor.velocity != 0 or self.mode != "idle":
                self.mode, self.target, self._seeking = "idle", None, False
                self._drive(0)
            return
        out = self.motor.velocity
        if out != 0 and self._stall_check(now, pos, out):
            return
        if out != 0 and self._at_end(out, pos):
            self._drive(0)
            if self.mode == "hold":
                self._seeking = False
            else:
                self.mode = "idle"
            return
        if self.mode == "hold":
            self._hold_step(pos)
        elif self.mode in ("extend", "retract") and out == 0:
            direction = 1 if self.mode == "extend" else -1
            if self._at_end(direction, pos):
                self.mode = "idle"
            else:
                self._drive(FULL * direction)  # after a reversal's tick at rest

    def _hold_step(self, pos: float) -> None:
        assert self.target is not None
        err = self.target - pos
        out = self.motor.velocity
        if out != 0:
            if (out > 0 and err <= self.hysteresis) or (out < 0 and err >= -self.hysteresis):
                self._drive(0)
                self._seeking = False
            return
        band = self.hysteresis if self._seeking else self.tolerance
        direction = _sign(err) if abs(err) > band else 0
        if direction != 0 and not self._at_end(direction, pos):
            self._drive(FULL * direction)
        else:
            self._seeking = False

    def _run_to_end(self, direction: int) -> None:
        self._refuse_if_faulted()
        self.mode, self.target = ("extend" if direction > 0 else "retract"), None
        if self._at_end(direction, self.position):
            self.mode = "idle"
            self._drive(0)
            return
        out = self.motor.velocity
        # reverse through rest; the next tick starts the run
        self._drive(0 if out != 0 and _sign(out) != direction else FULL * direction)

    def _at_end(self, direction: float, pos: float) -> bool:
        return (direction > 0 and pos >= END_HIGH) or (direction < 0 and pos <= END_LOW)

    def _drive(self, velocity: int) -> None:
        if _sign(velocity) != _sign(self.motor.velocity):
            self._ref_time = None  # a new driven period: the stall guard starts over
        self.motor.set_velocity(velocity)

    def _stall_check(self, now: float, pos: float, out: int) -> bool:
        """Latch a fault when the last `stall_time` s of driving made too little progress."""
        if self._ref_time is None:
            self._ref_pos, self._ref_time = pos, now
            return False
        progress = (pos - self._ref_pos) * _sign(out)
        needed = self.stall_min_change * abs(out) / FULL
        if progress >= needed and progress > 0:
            self._ref_pos, self._ref_time = pos, now
            return False
        if now - self._ref_time < self.stall_time - 1e-9:
            return False
        way = "up" if out > 0 else "down"
        if progress < -max(needed, self.stall_min_change):
            reason = (f"lift stalled: moved the wrong way by {-progress:.3f} in "
                      f"{now - self._ref_time:.1f} s while driven {way} at {pos:.2f} - "
                      "check the lift_motor polarity and the lift_pot calibration")
        else:
            reason = (f"lift stalled: moved {max(progress, 0.0):.3f} in "
                      f"{now - self._ref_time:.1f} s while driven {way} at {pos:.2f} "
                      f"- needs {needed:.3f}")
        self.mode, self.target, self._seeking = "idle", None, False
        self._drive(0)
        self.latch.trip(reason)
        return True

    def _refuse_if_faulted(self) -> None:
        if self.fault:
            raise RequestError("fault", self.fault)
        if not math.isfinite(self.position):
            raise RequestError("fault", "lift position unknown: no reading from lift_pot")
