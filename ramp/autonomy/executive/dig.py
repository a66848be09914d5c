"""Excavate: lower the ladder, run the chain, creep forward, stop at a target load or time.

At the digging spot (facing the far wall): `ble:lift.pos=(0.0)` lowers the ladder into the
regolith (0 is retracted, the digging position, SPEC 2.1); once the lift reads down, the chain
runs at `chain_speed_pct` and the robot creeps forward at `creep_speed_pct` for the trench's
`creep_m`, then digs standing. It stops at `dig_target_kg` in the bin (`ble:load.kg`, polled:
a full bin), after the dig the run's time allows (`ramp.statemachine.productivity`: the
fewest cycles that dig the most, the last deposit before the end) or after `dig_max_s`,
stops the BLE (chain, and the lift's hold, so the watchdog has nothing left to guard) and
the wheels, and marks the trench dug so no later spot repeats it. A chain that brings
nothing in (outside the digging region, or the lift not down) fails the step instead of
spinning for the whole run.
"""

from __future__ import annotations

import math

from ramp.autonomy.executive.plan import OUT_M_NOTE, plan_home
from ramp.autonomy.executive.step import Step
from ramp.autonomy.odometry import between
from ramp.autonomy.planning.geometry import Pose
from ramp.statemachine import Status
from ramp.statemachine.productivity import plan_dig

LOWERED = 0.05  # lift position that counts as down
LOWER_TIMEOUT_S = 15.0  # a full stroke takes about 10 s (SPEC 2.1)
NOTHING_IN_S = 15.0  # digging this long with the load not rising: something is wrong
RESEND_S = 0.25
CREEP_OVERSHOOT_M = 0.05  # how far past `creep_m` a creep may end, for the way home's estimate


class Excavate(Step):
    def begin(self, now: float) -> None:
        robot = self.kit.robot
        self.phase = "lowering"
        self.dig_began = math.nan
        self.dig_s = math.inf
        self.load0 = 0.0
        self.crept = 0.0
        self.creeping = False
        self.sent_at = -math.inf
        self.odom0 = self.kit.perception.odometry.pose
        robot.moving = True
        robot.send("ble:lift.pos=(0.0)")
        robot.poll_now()

    def step(self, now: float, dt: float) -> Status:
        kit, robot, s = self.kit, self.kit.robot, self.kit.settings
        if self.phase == "lowering":
            if robot.fresh(self.started_at) and robot.lift_pos <= LOWERED:
                self.phase = "digging"
                self.dig_began = now
                self.load0 = robot.load_kg
                self.dig_s = self._plan(now)
                robot.send(f"ble:chain.vel=({round(s.chain_speed_pct)})")
                self.creeping = True
            elif now - self.started_at > LOWER_TIMEOUT_S:
                return Status.failed(f"the ladder did not come down (lift at "
                                     f"{robot.lift_pos:.2f})")
            return Status.running()
        load = robot.load_kg
        if math.isfinite(load):
            self.ctx.bin_kg = load
        self.crept = between(self.odom0, kit.perception.odometry.pose)[0]
        creep_m = self.ctx.dig_sites.config.creep_m if self.ctx.dig_sites else 0.3
        if self.creeping and self.crept >= creep_m:
            self.creeping = False
            robot.halt_base()
        elif self.creeping and now - self.sent_at >= RESEND_S:
            robot.drive(round(s.creep_speed_pct), 0.0)
            self.sent_at = now
        robot.moving = True  # the chain runs: keep the watchdog fed
        digging_s = now - self.dig_began
        if load >= s.dig_target_kg or digging_s >= min(self.dig_s, s.dig_max_s):
            return self._finish(load, digging_s)
        if digging_s > NOTHING_IN_S and load - self.load0 < 0.2:
            robot.send("ble:ble.stop=()")
            robot.halt_base()
            return Status.failed(f"no regolith came in after {digging_s:.0f} s of digging")
        return Status.running()

    def _plan(self, now: float) -> float:
        """This dig's length: the largest share of the run's time left that still lets the
        last deposit land before the end."""
        ctx, s = self.ctx, self.kit.settings
        rate = float(ctx.notes.get("dig_rate_kg_s", s.dig_rate_kg_s))
        load0 = self.load0 if math.isfinite(self.load0) else 0.0
        full_s = max(0.0, s.dig_target_kg - load0) / max(rate, 1e-3)
        b = ctx.budget
        self._expect_home()
        return plan_dig(b.left(now), b.margin_s, ctx.estimates, full_s).dig_s

    def _expect_home(self) -> None:
        """Until the way home has been driven once, expect it at the way out's pace over its
        own planned length. It ends with the docking approach and the reverse onto the wall,
        so it is often a third longer than the way out (randomized seed 309: 79 s out over
        3.4 m, 108 s home over 4.7 m). Taken as long as the way out, it sized the first dig
        for a second cycle that then did not fit, and the run ended at 323 s with 20 kg."""
        ctx = self.ctx
        est = ctx.estimates
        out_m = ctx.notes.pop(OUT_M_NOTE, None)
        pose = self.kit.pose()
        if est.home_measured or not out_m or ctx.planner is None or pose is None:
            return
        # From where the creep ends, and from a little past it (the creep overshoots): by an
        # obstacle, whether the robot can turn there or must drive around first changes
        # within centimetres (randomized seed 306: 4.6 m planned from one pose, 7.1 m from
        # 2.5 cm further on, and 7.1 m it was).
        creep_m = ctx.dig_sites.config.creep_m if ctx.dig_sites else 0.0
        longest = 0.0
        for ahead in (creep_m, creep_m + CREEP_OVERSHOOT_M):
            end = Pose(pose.x + ahead * math.cos(pose.yaw), pose.y + ahead * math.sin(pose.yaw),
                       pose.yaw)
            home, _ = plan_home(ctx.planner, end, headings=False)
            if home.ok:
                longest = max(longest, home.length_m)
        est.home_s = max(est.home_s, est.trip_s * longest / out_m)

    def end(self) -> None:
        # Left before the target (the run's end sent it home, a fault, an operator): a spot
        # that gave regolith has its trench now, and is not dug again.
        if self.phase == "digging" and self.kit.robot.load_kg - self.load0 >= 1.0:
            self._mark_dug()

    def _finish(self, load: float, digging_s: float) -> Status:
        robot = self.kit.robot
        robot.send("ble:ble.stop=()")  # the chain, and the lift's hold: nothing left armed
        robot.halt_base()
        robot.moving = False
        self._mark_dug()
        if digging_s > NOTHING_IN_S and math.isfinite(self.load0):
            rate = (load - self.load0) / digging_s
            if rate > 0.0:
                self.ctx.notes["dig_rate_kg_s"] = rate
        return Status.done(f"{load:.1f} kg in the bin after {digging_s:.0f} s of digging")

    def _mark_dug(self) -> None:
        ctx = self.ctx
        spot = ctx.dig_spot
        if spot is not None:
            if ctx.dig_sites is not None:
                ctx.dig_sites.mark_dug(spot, max(0.0, self.crept))
            ctx.dig_spots_done.append(spot)
            ctx.dig_spot = None
        self.phase = "dug"
