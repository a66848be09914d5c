"""Node tasks for a supervisor (the fleet's orders, SPEC 14): go to a pose, dig, dump.

The RMC mission decides for itself where to go; a fleet order says where, node by node. So
that both drive the same way, a node task is a list of the executive's own activities
(`ACTIVITIES`: the mission's acquire, localizations, 3D scan, plans, crossing, dig, dock,
deposit), run in order on the mission's context and kit while the mission machine is held
(an endpoint's mission waits held for its order; see ramp/autonomy/command.py). There is no
second planner and no second localizer: the tracker, the planner built from the 3D scan and
`PlanDriver` (stops to localize, re-plans from every fix) are the mission's.

    goto x y [theta]  acquire control; a fix if the pose is unknown or not confident (the
                      first with the start box, later by re-levelling and matching the walls);
                      the 3D scan from the start region's vantage point if the target lies
                      beyond the start region and no obstacle map exists yet; then `GoTo`:
                      plan on the obstacle map (on the start region's own planners before any
                      map: only targets inside the start region), drive, a fix at the end
    dig [seconds]     acquire control; the mission's Excavate from where the robot stands
                      (its front must be in the digging region): ladder down, chain, creep,
                      until the bin is full, `seconds` (default: `dig_max_s`) or nothing
                      comes in
    dump              acquire control; plan home, cross home, dock, deposit, decouple: the
                      mission's way to the collector and its deposit

One task at a time. Its `status()`: `kind`, `id` (the supervisor's), `state` (`running`,
`waiting` while an operator holds control, `held` while a supervisor paused it, `done`,
`failed`, `cancelled`), `step` (the activity running), `reason` (the newest step's result, or
why it failed or waits), `target`.

What happens on the way, as in the mission: a lost pose stops the robot, re-levels,
re-localizes and goes on from the plan (at most `MAX_RECOVERIES` times); a fault or failure
stops the robot and fails the task, saying why (so does a step past its time-out: the
mission's for its states, `GOTO_TIMEOUT_S` for a goto); an operator's takeover makes it wait (it
never takes control from one) and go on, re-localized, once control is free; `hold` stops the
robot and `resume` starts the task again from its first step (control, pose, plan).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ramp.autonomy import arena
from ramp.autonomy.executive import ACTIVITIES
from ramp.autonomy.executive.crossing import fix_spacing
from ramp.autonomy.executive.dig import Excavate
from ramp.autonomy.executive.drive import PlanDriver
from ramp.autonomy.executive.kit import Kit, yaw_error
from ramp.autonomy.executive.plan import start_planners
from ramp.autonomy.executive.step import Step
from ramp.autonomy.planning import Planner, PlanResult, Pose
from ramp.statemachine import Mission, StandStill, Status
from ramp.statemachine.status import StatusKind
from ramp.statemachine.table import STATE

log = logging.getLogger("ramp.autonomy.tasks")

GOTO, DIG, DUMP = "goto", "dig", "dump"
KINDS = (GOTO, DIG, DUMP)
RUNNING, WAITING, HELD, DONE, FAILED, CANCELLED = (
    "running", "waiting", "held", "done", "failed", "cancelled")
ACTIVE = (RUNNING, WAITING, HELD)
REACHED_M = 0.15  # a goto already this near its target (and turned) is there
REACHED_YAW_DEG = 10.0
MAX_RECOVERIES = 2
SETTLE = "settle"  # the robot stands still before a recovery's scans
RECOVERY = ("relevel", "rescan", "relocalize")
#: After a recovery, where a step goes on (as the mission's RESUME_AT).
RESUME_AT = {"cross_home": "plan_path_home", "dock": "plan_path_home"}
#: Steps that move the robot across the ground: never while the pose is not confident.
DRIVING_STEPS = frozenset({GOTO, "prepare_for_scan", "cross_home", "dock", "decouple"})
#: Time-outs of the steps that are not the mission's states (theirs are in its table).
GOTO_TIMEOUT_S = 300.0
DIG_EXTRA_S = 60.0  # beyond `dig_max_s`: the ladder's stroke and the stop


def in_arena(x: float, y: float) -> bool:
    return 0.0 <= x <= arena.ARENA_LENGTH_M and 0.0 <= y <= arena.ARENA_WIDTH_M


def in_start_region(x: float) -> bool:
    return x < arena.START_END_X_M


class GoTo(Step):
    """Plan to `target` (x, y, optional yaw) and drive there (see the module docstring)."""

    def __init__(self, kit: Kit, target: tuple[float, float, float | None]) -> None:
        super().__init__(kit)
        self.target = target
        self.driver: PlanDriver | None = None

    def step(self, now: float, dt: float) -> Status:
        if self.driver is None:
            pose = self.kit.pose()
            if pose is None:
                return Status.lost("no pose to plan from")
            if self._there(pose):
                return Status.done(f"at x {pose.x:.2f} y {pose.y:.2f}")
            planner = self._planner()
            if planner is None:
                return Status.failed("no obstacle map: x beyond the start region needs the "
                                     "3D scan first")
            result = self._plan(pose)
            if not result.ok:
                return Status.failed(f"no way to x {self.target[0]:.2f} y "
                                     f"{self.target[1]:.2f}: {result.reason}")
            self.kit.log["planned"].append(("goto", result))
            self.driver = PlanDriver(self, result.legs, replan=self._plan, final_fix=True,
                                     check=planner.accepts,
                                     relocalize_every_m=fix_spacing(self.kit, result))
        status = self.driver.tick(now)
        if status.kind is StatusKind.DONE:
            pose = self.kit.pose()
            where = f"x {pose.x:.2f} y {pose.y:.2f} yaw {math.degrees(pose.yaw):.0f} deg" \
                if pose is not None else "the target"
            return Status.done(f"reached {where}")
        return status

    def end(self) -> None:
        if self.driver is not None:
            self.driver.cancel()

    def _there(self, pose: Pose) -> bool:
        x, y, yaw = self.target
        return (math.hypot(pose.x - x, pose.y - y) <= REACHED_M
                and (yaw is None or yaw_error(pose.yaw, yaw) <= math.radians(REACHED_YAW_DEG)))

    def _planner(self) -> Planner | None:
        if self.ctx.planner is not None:
            return self.ctx.planner
        if not in_start_region(self.target[0]):
            return None
        return start_planners().coarse

    def _plan(self, pose: Pose, headings: bool = True) -> PlanResult:
        x, y, yaw = self.target
        planner = self._planner()
        if planner is None:
            return PlanResult((), "no obstacle map")
        result = planner.plan(pose, (x, y), goal_yaw=yaw, headings=headings)
        if not result.ok and self.ctx.planner is None:  # planned on the start region's
            result = start_planners().fine.plan(pose, (x, y), goal_yaw=yaw, headings=headings)
        return result


class DigHere(Excavate):
    """The mission's Excavate where the robot stands, for `seconds` at most (or until the bin
    is full); its front must be in the digging region."""

    def __init__(self, kit: Kit, seconds: float | None) -> None:
        super().__init__(kit)
        self.seconds = seconds
        self.outside = ""

    def begin(self, now: float) -> None:
        pose = self.kit.pose()
        front = None if pose is None else pose.x + arena.ROBOT_LENGTH_M / 2 * math.cos(pose.yaw)
        if front is not None and front < arena.OBSTACLE_END_X_M:
            self.outside = (f"the robot's front is at x {front:.2f}, outside the digging "
                            f"region (x >= {arena.OBSTACLE_END_X_M:g})")
            self.phase = "refused"
            return
        self.ctx.dig_spot = None  # not one of the mission's spots: nothing to mark dug
        super().begin(now)

    def step(self, now: float, dt: float) -> Status:
        if self.outside:
            return Status.failed(self.outside)
        return super().step(now, dt)

    def _plan(self, now: float) -> float:
        s = self.kit.settings
        return s.dig_max_s if self.seconds is None else min(self.seconds, s.dig_max_s)


@dataclass
class Task:
    kind: str
    task_id: str
    target: tuple[float, float, float | None] | None = None
    seconds: float | None = None
    state: str = RUNNING
    step: str = ""
    reason: str = ""
    steps: list[str] = field(default_factory=list)
    recoveries: int = 0

    def status(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "id": self.task_id, "state": self.state,
                               "step": self.step, "reason": self.reason}
        if self.target is not None:
            x, y, yaw = self.target
            out["target"] = {"x": x, "y": y, "theta": yaw}
        return out


class NodeTasks:
    """Runs one node task at a time on the mission's kit and context; `tick` at the
    mission's rate (the command endpoint's task)."""

    def __init__(self, mission: Mission, kit: Kit) -> None:
        self.mission = mission
        self.kit = kit
        self.task: Task | None = None
        self._activity: Any = None
        self._step_started = 0.0
        self._fixed = False  # a fix was made by a task (or the mission)

    # -- what the endpoint asks ---------------------------------------------------------------
    @property
    def active(self) -> bool:
        return self.task is not None and self.task.state in ACTIVE

    def status(self) -> dict[str, Any] | None:
        return None if self.task is None else self.task.status()

    def start(self, kind: str, task_id: str = "", *, x: float | None = None,
              y: float | None = None, theta: float | None = None,
              seconds: float | None = None) -> str:
        """Start a task; "" when started, else why not."""
        if kind not in KINDS:
            return f"unknown task {kind!r}"
        if self.active:
            assert self.task is not None
            return (f"task {self.task.kind} {self.task.task_id!r} is {self.task.state}: "
                    "cancel it first")
        target = None
        if kind == GOTO:
            if x is None or y is None:
                return "goto needs x and y (arena frame, m)"
            if not in_arena(x, y):
                return (f"x {x:g} y {y:g} is outside the arena (0..{arena.ARENA_LENGTH_M:g} "
                        f"by 0..{arena.ARENA_WIDTH_M:g} m)")
            target = (x, y, theta)
        self.task = Task(kind, task_id, target, seconds)
        self._begin(self.task)
        log.info("task %s %r started: %s", kind, task_id, ", ".join(self.task.steps))
        return ""

    def cancel(self, reason: str) -> bool:
        """Stop the task and the robot; False when none runs."""
        if not self.active or self.task is None:
            return False
        self._stop_activity()
        self._stop_robot()
        self.task.state, self.task.reason = CANCELLED, reason
        return True

    def hold(self, reason: str) -> None:
        """A supervisor's pause: the robot stops; `resume` starts the task again."""
        if self.task is None or self.task.state not in (RUNNING, WAITING):
            return
        self._stop_activity()
        self._stop_robot()
        self.task.state, self.task.reason = HELD, reason

    def resume(self) -> bool:
        """Start a held task again from its first step; False when none is held."""
        if self.task is None or self.task.state != HELD:
            return False
        self._begin(self.task)
        return True

    # -- the task ---------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        task = self.task
        if task is None or task.state not in (RUNNING, WAITING):
            return
        robot = self.kit.robot
        if task.state == WAITING:
            owner = robot.owner or "none"
            if owner in ("none", robot.owner_name):
                log.info("task %s: control is free again: starting over", task.kind)
                self._begin(task)
            return
        if self._activity is None:
            if not task.steps:
                task.state = DONE
                robot.moving = False
                return
            self._start_step(task, task.steps.pop(0), now)
        timeout = self._timeout(task.step)
        if task.step in DRIVING_STEPS and not self._confident():
            status = Status.lost("the pose is not confident")
        elif timeout is not None and now - self._step_started >= timeout:
            status = Status.failed(f"no result after {timeout:g} s")
        else:
            status = self._activity.tick(now, dt)
        if status.is_running:
            return
        kind = status.kind
        self._stop_activity()
        if kind is StatusKind.DONE:
            task.reason = status.reason or f"{task.step} done"
            if task.step in ("initial_localization", "relocalize"):
                self._fixed = True
            if not task.steps:
                task.state = DONE
                robot.moving = False
                log.info("task %s %r done: %s", task.kind, task.task_id, task.reason)
            return
        if kind is StatusKind.OPERATOR:
            robot.motion_stopped_by_others()
            task.state, task.reason = WAITING, f"waiting: {status.reason}; an order never " \
                "takes control from an operator"
            return
        if kind is StatusKind.LOST and task.recoveries < MAX_RECOVERIES \
                and task.step not in RECOVERY:
            task.recoveries += 1
            self._stop_robot()
            resume_at = RESUME_AT.get(task.step, task.step)
            task.steps = [SETTLE, *RECOVERY, resume_at, *task.steps]
            task.reason = f"lost in {task.step} ({status.reason}): re-localizing"
            return
        self._stop_robot()
        task.state = FAILED
        task.reason = f"{task.step}: {status.reason}"
        log.warning("task %s %r failed: %s", task.kind, task.task_id, task.reason)

    # -- inside -----------------------------------------------------------------------------
    def _begin(self, task: Task) -> None:
        self._stop_activity()
        task.state, task.step, task.reason = RUNNING, "", "starting"
        task.steps = self._steps(task)

    def _steps(self, task: Task) -> list[str]:
        steps = ["acquire_control"]
        if not self._confident():
            fixed = self._fixed or self.mission.localization != "none" \
                or self.kit.tracker.fixes > 0
            steps += list(RECOVERY) if fixed else ["initial_localization"]
        needs_map = task.kind == DUMP or (
            task.target is not None and not in_start_region(task.target[0]))
        if needs_map and self.mission.context.planner is None:
            steps += ["prepare_for_scan", "scan_for_obstacles", "detect_obstacles"]
        if task.kind == GOTO:
            steps.append(GOTO)
        elif task.kind == DIG:
            steps.append(DIG)
        else:
            steps += ["plan_path_home", "cross_home", "dock", "deposit", "decouple"]
        return steps

    def _timeout(self, name: str) -> float | None:
        if name == GOTO:
            return GOTO_TIMEOUT_S
        if name == DIG:
            return self.kit.settings.dig_max_s + DIG_EXTRA_S
        if name not in STATE:
            return None
        return self.mission.config.timeout_of(name)  # the mission's, as configured

    def _start_step(self, task: Task, name: str, now: float) -> None:
        task.step = name
        self._step_started = now
        make: Callable[[], Any]
        if name == GOTO:
            assert task.target is not None
            target = task.target
            make = lambda: GoTo(self.kit, target)  # noqa: E731
        elif name == DIG:
            make = lambda: DigHere(self.kit, task.seconds)  # noqa: E731
        elif name == SETTLE:
            make = lambda: StandStill(self.mission.config.stop_settle_s)  # noqa: E731
        else:
            cls = ACTIVITIES[name]
            make = lambda: cls(self.kit)  # noqa: E731
        self._activity = make()
        self._activity.start(self.mission.context, now)

    def _confident(self) -> bool:
        ctx = self.mission.context
        return self.kit.pose() is not None and \
            ctx.pose_is_confident(self.mission.config.min_pose_confidence)

    def _stop_activity(self) -> None:
        act, self._activity = self._activity, None
        if act is not None:
            try:
                act.stop()
            except Exception:
                log.exception("task: the %s step's stop raised", self.task.step
                              if self.task else "?")
                self._stop_robot()

    def _stop_robot(self) -> None:
        """Stop the robot, unless someone else holds control (their motion is theirs)."""
        robot = self.kit.robot
        if robot.owner == robot.owner_name:
            robot.stop_all()
        else:
            robot.motion_stopped_by_others()
