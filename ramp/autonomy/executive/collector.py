"""At the collector: Dock, Deposit, Decouple (thesis figure 5.35).

- **Dock**: the crossing home stopped a few centimetres short of the x = 0 wall, square to
  it; back up slowly until both docking buttons (`base:l_button.press`, `r_button.press`,
  on the rear corners) read pressed. When one is pressed and the other is not, the rear is a
  little askew: the side still off the wall backs up alone (a pivot about the other side's
  wheels, SPEC 2.3 direction +-135) until it touches too. Regolith counts as delivered with
  the rear within 0.15 m of the wall (SPEC 6.1), so one button held for `ONE_BUTTON_S` is
  accepted as docked; none after `MAX_BACK_M` of travel fails the step.
- **Deposit**: raise the bin (`ble:lift.pos=(1.0)`) and wait for `ble:load.kg` to fall below
  `dump_done_kg`, or to stop falling; the bin's drop is the delivered estimate.
- **Decouple**: lower the bin (`ble:lift.pos=(0.0)`) while driving straight out `CLEAR_M`,
  then stop the BLE so nothing is left for the watchdog to guard.
"""

from __future__ import annotations

import math

from ramp.autonomy.executive.step import Step
from ramp.autonomy.odometry import between
from ramp.statemachine import Status

ONE_BUTTON_S = 3.0
MAX_BACK_M = 0.30
RESEND_S = 0.25
RAISED = 0.95  # lift position that counts as up (dumping starts above 0.8)
LOWERED = 0.05
LIFT_TIMEOUT_S = 20.0  # a full stroke takes about 10 s (SPEC 2.1)
STILL_FALLING_S = 3.0  # the load has not fallen for this long: the bin is as empty as it gets
CLEAR_M = 0.30  # decouple: out this far, enough for the planner's way out to turn


class Dock(Step):
    def begin(self, now: float) -> None:
        self.odom0 = self.kit.perception.odometry.pose
        self.one_since: float | None = None
        self.sent: tuple[int, float] | None = None
        self.sent_at = -math.inf
        self.kit.robot.poll_now()

    def step(self, now: float, dt: float) -> Status:
        robot, s = self.kit.robot, self.kit.settings
        robot.moving = True
        left, right = robot.buttons if robot.fresh(self.started_at) else (False, False)
        if left and right:
            robot.halt_base()
            robot.moving = False
            return Status.done("both docking buttons pressed")
        back = -between(self.odom0, self.kit.perception.odometry.pose)[0]
        speed = round(s.dock_speed_pct)
        if left or right:
            if self.one_since is None:
                self.one_since = now
            if now - self.one_since >= ONE_BUTTON_S:
                robot.halt_base()
                robot.moving = False
                side = "left" if left else "right"
                return Status.done(f"only the {side} docking button pressed; the rear is "
                                   "at the wall")
            # the side still off the wall backs up alone
            self._drive(speed, 135.0 if left else -135.0, now)
            return Status.running()
        self.one_since = None
        if back > MAX_BACK_M:
            robot.halt_base()
            return Status.failed(f"backed up {back:.2f} m and no docking button pressed")
        self._drive(speed, 180.0, now)
        return Status.running()

    def _drive(self, speed: int, direction: float, now: float) -> None:
        if self.sent != (speed, direction) or now - self.sent_at >= RESEND_S:
            self.kit.robot.drive(speed, direction)
            self.sent = (speed, direction)
            self.sent_at = now


class Deposit(Step):
    def begin(self, now: float) -> None:
        robot = self.kit.robot
        self.load0 = math.nan
        self.lowest = math.inf
        self.lowest_at = now
        robot.moving = True
        robot.send("ble:lift.pos=(1.0)")
        robot.poll_now()

    def step(self, now: float, dt: float) -> Status:
        robot, ctx = self.kit.robot, self.ctx
        robot.moving = True
        if not robot.fresh(self.started_at):
            return Status.running()
        load = robot.load_kg
        if math.isnan(self.load0):
            self.load0 = load
        if math.isfinite(load):
            ctx.bin_kg = load
            if load < self.lowest - 0.05:
                self.lowest, self.lowest_at = load, now
        if robot.lift_pos < RAISED:
            if now - self.started_at > LIFT_TIMEOUT_S:
                return Status.failed(f"the bin did not rise (lift at {robot.lift_pos:.2f})")
            return Status.running()
        empty = load <= self.kit.settings.dump_done_kg
        if empty or now - self.lowest_at >= STILL_FALLING_S:
            dumped = max(0.0, self.load0 - load)
            ctx.delivered_kg += dumped
            ctx.deposits += 1
            return Status.done(f"{dumped:.1f} kg out of the bin, {load:.1f} kg left")
        return Status.running()


class Decouple(Step):
    def begin(self, now: float) -> None:
        robot = self.kit.robot
        self.odom0 = self.kit.perception.odometry.pose
        self.driving = True
        self.sent_at = -math.inf
        robot.moving = True
        robot.send("ble:lift.pos=(0.0)")
        robot.poll_now()

    def step(self, now: float, dt: float) -> Status:
        robot, s = self.kit.robot, self.kit.settings
        robot.moving = True
        out = between(self.odom0, self.kit.perception.odometry.pose)[0]
        if self.driving and out >= CLEAR_M:
            self.driving = False
            robot.halt_base()
        elif self.driving and now - self.sent_at >= RESEND_S:
            robot.drive(round(min(s.drive_speed_pct, 30.0)), 0.0)
            self.sent_at = now
        if not self.driving and robot.fresh(self.started_at) and robot.lift_pos <= LOWERED:
            robot.send("ble:ble.stop=()")
            robot.moving = False
            return Status.done(f"clear of the collector by {out:.2f} m, bin down")
        if now - self.started_at > LIFT_TIMEOUT_S:
            return Status.failed(f"the bin did not come down (lift at {robot.lift_pos:.2f})")
        return Status.running()
