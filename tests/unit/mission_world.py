"""A scripted world and small activities for the mission state machine's tests.

The world is a MARTE reduced to what the machine's decisions depend on: a pose that moves
toward a goal at a set speed, a bin that fills while the chain runs and empties when the bin
is raised at the collector, the control owner, whether the localizer can find the walls, and
a script of what goes wrong (pose lost at a time, faults and failures in a state, an
activity that raises, an operator who takes control and gives it back). Everything runs on
the virtual time `run` steps; nothing sleeps.

The activities are real in the sense that matters here: they keep the `Activity` contract
(start, tick, stop; never block), command the world the way an executive commands the robot
over MCP (and get `not_owner` or `fault` answers back), and hand over through the
`MissionContext`. The world records every command and flags any drive commanded while the
mission's pose was not confident.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from ramp.autonomy.planning import DigSpot, Disc, Pose, Trench
from ramp.statemachine import (
    Executive,
    Mission,
    MissionConfig,
    MissionContext,
    StateChange,
    Status,
)

DOCK_X = 0.6  # footprint centre with the rear on the x = 0 wall
COLLECTOR_Y = 1.94
CLEAR_X = 1.2  # where decoupling leaves the robot
SPOTS = (1.2, 1.9, 2.6, 3.3)  # y of the digging spots, x = 5.2 (never the same twice)
SPEED_M_S = 0.3
CREEP_M_S = 0.02
LIFT_PER_S = 0.5
DRAIN_KG_S = 5.0


@dataclass
class Script:
    """What the world does to the mission."""

    dig_kg_s: float = 0.25
    target_kg: float = 8.0  # excavate stops at this load
    lose_pose_at: tuple[float, ...] = ()  # the localizer loses the walls
    lose_pose_finishing: dict[str, int] = field(default_factory=dict)  # lost as they finish
    relocalize_failures: int = 0  # the next relocalize tries that fail
    faults: dict[str, int] = field(default_factory=dict)  # state -> fault answers to give
    failures: dict[str, int] = field(default_factory=dict)  # state -> `failed` statuses
    raises: dict[str, tuple[str, int]] = field(default_factory=dict)  # state -> (where, n)
    takeovers: tuple[tuple[float, float], ...] = ()  # (operator acquires, releases) times
    stuck: set[str] = field(default_factory=set)  # states whose activity never finishes


class World:
    def __init__(self, script: Script | None = None) -> None:
        self.script = script or Script()
        self.t = 0.0
        self.x, self.y, self.yaw = 0.75, 2.9, 0.0
        self.goal: tuple[float, float] | None = None
        self.speed = 0.0
        self.chain = False
        self.lift = 0.0
        self.lift_target = 0.0
        self.bin_kg = 0.0
        self.delivered_kg = 0.0
        self.owner = "none"
        self.localized = True
        self.stops: list[float] = []  # stop_robot calls
        self.commands: list[tuple[float, str, str]] = []  # accepted: (t, state, what)
        self.refused: list[tuple[float, str, str]] = []
        self.drove_while_lost: list[tuple[float, str]] = []
        self.mission: Mission | None = None

    # -- what the mission and the operator do to it ------------------------------------------
    def stop_robot(self) -> None:
        """The mission's `stop_robot`: robot:robot.stop=() (accepted from anyone)."""
        self.stops.append(self.t)
        self._halt()

    def operator_acquires(self) -> None:
        self.owner = "operator"
        self._halt()  # an acquire by a new owner stops all motion (SPEC 2.2)

    def command(self, state: str, what: str, ctx: MissionContext, drives: bool = False
                ) -> str | None:
        """One MCP request from an activity: None if accepted, else the error code."""
        if self.owner not in ("none", "autonomy"):
            self.refused.append((self.t, state, what))
            return "not_owner"
        if self.script.faults.get(state, 0) > 0:
            self.script.faults[state] -= 1
            self.refused.append((self.t, state, what))
            return "fault"
        if drives:
            assert self.mission is not None
            if not ctx.pose_is_confident(self.mission.config.min_pose_confidence):
                self.drove_while_lost.append((self.t, state))
        self.commands.append((self.t, state, what))
        return None

    # -- physics -------------------------------------------------------------------------------
    def _halt(self) -> None:
        self.speed = 0.0
        self.goal = None
        self.chain = False

    @property
    def docked(self) -> bool:
        return self.x <= DOCK_X + 0.02

    def step(self, dt: float) -> None:
        self.t = round(self.t + dt, 9)
        for at in self.script.lose_pose_at:
            if self.t - dt < at <= self.t:
                self.localized = False
        for on, off in self.script.takeovers:
            if self.t - dt < on <= self.t:
                self.operator_acquires()
            if self.t - dt < off <= self.t:
                self.owner = "none"
        if self.goal is not None and self.speed > 0:
            gx, gy = self.goal
            d = math.hypot(gx - self.x, gy - self.y)
            s = min(d, self.speed * dt)
            if d > 1e-9:
                self.x += s * (gx - self.x) / d
                self.y += s * (gy - self.y) / d
        if self.chain:
            self.bin_kg += self.script.dig_kg_s * dt
        self.lift += max(-LIFT_PER_S * dt, min(LIFT_PER_S * dt, self.lift_target - self.lift))
        if self.lift >= 0.99 and self.docked and self.bin_kg > 0:
            out = min(self.bin_kg, DRAIN_KG_S * dt)
            self.bin_kg -= out
            self.delivered_kg += out

    def localize(self, ctx: MissionContext) -> None:
        """The localizer's task, before each mission tick: dead reckoning between scans, its
        confidence falling when the walls are lost."""
        if ctx.pose is None:
            return
        ctx.pose = Pose(self.x, self.y, self.yaw)
        ctx.pose_confidence = 0.9 if self.localized else 0.2


# -- activities ----------------------------------------------------------------------------------
class Act:
    """Common to the test activities: the script's failures, faults and exceptions."""

    duration_s = 0.5

    def __init__(self, world: World, state: str) -> None:
        self.world = world
        self.state = state
        self.ctx = MissionContext()
        self.t0 = 0.0
        self.stopped = False

    def _maybe_raise(self, where: str) -> None:
        how = self.world.script.raises.get(self.state)
        if how and how[0] == where and how[1] > 0:
            self.world.script.raises[self.state] = (where, how[1] - 1)
            raise RuntimeError(f"{self.state} {where} broke")

    def start(self, ctx: MissionContext, now: float) -> None:
        self.ctx, self.t0 = ctx, now
        self._maybe_raise("start")

    def tick(self, now: float, dt: float) -> Status:
        assert not self.stopped, "ticked after stop"
        self._maybe_raise("tick")
        script = self.world.script
        if script.failures.get(self.state, 0) > 0:
            script.failures[self.state] -= 1
            return Status.failed(f"{self.state} could not")
        if self.state in script.stuck:
            return Status.running()
        status = self.step(now, dt)
        if status.kind.value == "done" and script.lose_pose_finishing.get(self.state, 0) > 0:
            script.lose_pose_finishing[self.state] -= 1
            self.world.localized = False
            self.ctx.pose_confidence = 0.2
        return status

    def step(self, now: float, dt: float) -> Status:
        if now - self.t0 < self.duration_s:
            return Status.running()
        return Status.done()

    def stop(self) -> None:
        self.stopped = True

    def send(self, what: str, drives: bool = False) -> Status | None:
        err = self.world.command(self.state, what, self.ctx, drives)
        return None if err is None else Status.from_mcp_error(err, what)


class AcquireControl(Act):
    def step(self, now: float, dt: float) -> Status:
        if self.world.owner not in ("none", "autonomy"):
            return Status.operator(f"{self.world.owner} holds control")
        self.world.owner = "autonomy"
        return Status.done("acquired as autonomy")


class Localize(Act):
    duration_s = 1.0

    def step(self, now: float, dt: float) -> Status:
        if now - self.t0 < self.duration_s:
            return Status.running()
        w = self.world
        if self.state == "relocalize" and w.script.relocalize_failures > 0:
            w.script.relocalize_failures -= 1
            return Status.lost("the walls do not match")
        if self.state == "initial_localization" and not w.localized:
            return Status.lost("no walls in the scan")
        w.localized = True
        self.ctx.pose = Pose(w.x, w.y, w.yaw)
        self.ctx.pose_confidence = 0.9
        self.ctx.pose_time_s = now
        return Status.done(f"at ({w.x:.2f}, {w.y:.2f})")


class Scan(Act):
    duration_s = 5.0

    def step(self, now: float, dt: float) -> Status:
        status = super().step(now, dt)
        if status.kind.value == "done":
            self.ctx.obstacle_scan = [now]
        return status


class Detect(Act):
    def step(self, now: float, dt: float) -> Status:
        self.ctx.rocks = [Disc(2.5, 1.0, 0.1)]
        self.ctx.craters = [Disc(3.5, 2.8, 0.12)]
        return Status.done("1 rock, 1 crater")


class PlanToDig(Act):
    def step(self, now: float, dt: float) -> Status:
        ctx = self.ctx
        if ctx.dig_spot is None:
            y = SPOTS[len(ctx.dig_spots_done) % len(SPOTS)]
            ctx.dig_spot = DigSpot(Pose(5.2, y, 0.0), Trench(5.8, y - 0.25, 6.35, y + 0.25),
                                   trip_m=5.0)
        ctx.notes["goal"] = (ctx.dig_spot.pose.x, ctx.dig_spot.pose.y)
        return Status.done(f"to ({ctx.dig_spot.pose.x:.1f}, {ctx.dig_spot.pose.y:.1f})")


class PlanHome(Act):
    def step(self, now: float, dt: float) -> Status:
        self.ctx.notes["goal"] = (DOCK_X, COLLECTOR_Y)
        return Status.done("to the collector")


class Cross(Act):
    def step(self, now: float, dt: float) -> Status:
        problem = self.send("base:base.drive", drives=True)
        if problem is not None:
            return problem
        w = self.world
        w.goal, w.speed = self.ctx.notes["goal"], SPEED_M_S
        if math.hypot(w.goal[0] - w.x, w.goal[1] - w.y) < 1e-6:
            w.speed = 0.0
            return Status.done("at the goal")
        return Status.running()


class Excavate(Act):
    def step(self, now: float, dt: float) -> Status:
        problem = self.send("ble:chain.vel", drives=True)
        if problem is not None:
            return problem
        w, ctx = self.world, self.ctx
        w.chain, w.lift_target = True, 0.0
        w.goal, w.speed = (w.x + 1.0, w.y), CREEP_M_S
        ctx.bin_kg = w.bin_kg
        if w.bin_kg >= w.script.target_kg:
            w.chain, w.speed = False, 0.0
            assert ctx.dig_spot is not None
            ctx.dig_spots_done.append(ctx.dig_spot)
            ctx.dig_spot = None
            return Status.done(f"{w.bin_kg:.1f} kg")
        return Status.running()

    def stop(self) -> None:
        super().stop()
        self.ctx.bin_kg = self.world.bin_kg


class Dock(Act):
    def step(self, now: float, dt: float) -> Status:
        if now - self.t0 < self.duration_s:
            return Status.running()
        if not self.world.docked:
            return Status.failed("the docking buttons are not pressed")
        return Status.done("both buttons pressed")


class Deposit(Act):
    def start(self, ctx: MissionContext, now: float) -> None:
        super().start(ctx, now)
        self.before_kg = self.world.bin_kg

    def step(self, now: float, dt: float) -> Status:
        problem = self.send("ble:lift.extend")
        if problem is not None:
            return problem
        w = self.world
        w.lift_target = 1.0
        self.ctx.bin_kg = w.bin_kg
        if w.lift >= 0.99 and w.bin_kg < 0.05:
            self.ctx.delivered_kg += self.before_kg - w.bin_kg
            self.ctx.deposits += 1
            return Status.done(f"{self.before_kg:.1f} kg out")
        return Status.running()


class Decouple(Act):
    def step(self, now: float, dt: float) -> Status:
        problem = self.send("base:base.drive", drives=True)
        if problem is not None:
            return problem
        w = self.world
        w.lift_target = 0.0
        w.goal, w.speed = (CLEAR_X, w.y), SPEED_M_S
        if w.lift <= 0.01 and abs(w.x - CLEAR_X) < 1e-6:
            w.speed = 0.0
            return Status.done("clear of the collector")
        return Status.running()


ACTIVITIES: dict[str, Callable[[World, str], Act]] = {
    "acquire_control": AcquireControl,
    "initial_localization": Localize,
    "prepare_for_scan": Act,
    "scan_for_obstacles": Scan,
    "detect_obstacles": Detect,
    "plan_path_to_dig": PlanToDig,
    "cross_to_dig": Cross,
    "excavate": Excavate,
    "plan_path_home": PlanHome,
    "cross_home": Cross,
    "dock": Dock,
    "deposit": Deposit,
    "decouple": Decouple,
    "relevel": Act,
    "rescan": Act,
    "relocalize": Localize,
}


def executive(world: World) -> Executive:
    """Every working state but `stop`, which keeps the machine's built-in StandStill."""
    return Executive({state: (lambda cls=cls, state=state: cls(world, state))
                      for state, cls in ACTIVITIES.items()})


@dataclass
class Run:
    world: World
    mission: Mission
    changes: list[StateChange]

    @property
    def path(self) -> list[str]:
        """The states entered, in order."""
        return [c.dest for c in self.changes]

    def entered(self, state: str) -> list[StateChange]:
        return [c for c in self.changes if c.dest == state]

    def run(self, until: float, dt: float = 0.1, poll_every: int = 5) -> Run:
        """Step world and mission to `until` or the mission's end; the link polls
        `robot.get` every `poll_every` ticks and feeds the owner to the mission."""
        n = 0
        while self.world.t < until - 1e-9 and not self.mission.over:
            self.world.step(dt)
            self.world.localize(self.mission.context)
            n += 1
            if n % poll_every == 0:
                self.mission.observe_control(self.world.owner)
            self.mission.tick(self.world.t, dt)
        return self


def make_run(script: Script | None = None, start: bool = True, **config: float) -> Run:
    world = World(script)
    mission = Mission(executive(world), world.stop_robot,
                      config=MissionConfig.from_mapping(config))
    world.mission = mission
    changes: list[StateChange] = []
    mission.add_listener(changes.append)
    if start:
        mission.start(world.t)
    return Run(world, mission, changes)
