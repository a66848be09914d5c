"""The mission: a `transitions` machine built from `ramp.statemachine.table`, ticked on the
injected clock.

Why this shape:

- **One thread, one clock.** `tick(now, dt)` is one iteration, run as a scheduler task.
  Every decision is taken inside it, in a fixed order, at most one per tick: the operator's
  control (`observe_control`), the end of the run, a reported fault (`report_fault`), a
  driving state without a confident pose, the state's timeout, the "head home now?" check,
  and then the activity's own status. Signals from outside are latched and acted on at the
  next tick, so a run is the same whatever order its inputs arrive in within one tick.
- **No threads.** The `transitions` `Timeout` mixin starts a `threading.Timer` per state;
  here timeouts are compared with `now` in the tick.
- **`queued=True`.** A trigger fired while a transition runs (the `resume` choice
  dispatching, a fault raised by an activity's `start`) waits its turn, so callbacks never
  nest and every state change is whole before the next begins.
- **`on_exception` stops the robot.** An exception from an activity or a callback is
  logged, the robot stopped (when the mission holds control), and it becomes a `fault`,
  which is retried a bounded number of times like any other, then waits for the operator.
- **It never drives while lost.** Every row into a driving state is guarded by
  `pose_confident` (the table adds it), and every tick in a driving state checks the pose.

What feeds it:

- `tick(now, dt)` from the scheduler, after the localizer has written `ctx.pose` and
  `ctx.pose_confidence` for this tick.
- `observe_control(owner)` with every `robot:control.owner` the link reads (`robot.get`),
  from the same MCP connection as the activities' commands, so the answers come in order.
- `report_fault(reason)` for what the link sees outside any activity: a `watchdog.state`
  of `tripped` while moving, a lost connection, a module in `fault`.

What it gives: `state` (the name the trace's `state` field carries), one log line per state
change (`mission: cross_to_dig -> excavate (finished)`) and the same as a `StateChange` to
every listener (`add_listener`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from transitions import EventData, Machine

from ramp.statemachine.activity import Activity, Executive, StandStill
from ramp.statemachine.context import Estimates, MissionContext, TimeBudget
from ramp.statemachine.settings import MissionConfig
from ramp.statemachine.status import Status
from ramp.statemachine.table import (
    DRIVING,
    FINAL,
    HALTING,
    INITIAL,
    OUTBOUND,
    RUN,
    STATE,
    STATES,
    TRANSITIONS,
    Resumes,
)
from ramp.statemachine.table import (
    RECOVERY as RECOVERY_STATES,
)

log = logging.getLogger("ramp.statemachine")
# `transitions` logs every callback at INFO; the one line per change that matters is ours.
logging.getLogger("transitions").setLevel(logging.WARNING)

#: The names a table row may use as a condition or a `before` callback.
CONDITIONS = ("pose_confident", "resuming", "step_retries_left", "must_relocalize",
              "out_of_tries", "time_for_another_cycle")
CALLBACKS = ("note_loss", "note_problem", "note_pause", "count_relocalize", "count_retry")
NO_OWNER = "none"  # what `robot:control.owner` reads when nobody holds control
#: What the mission knows of its pose (`Mission.localization`): no fix yet, a fix, lost (a
#: loss the machine took and has not recovered from), or re-localizing after a hand-back.
LOCALIZATION = ("none", "ok", "lost", "relocalizing")


class MissionError(RuntimeError):
    """The mission was used wrongly (started twice, an activity missing or misbehaving)."""


@dataclass(frozen=True)
class StateChange:
    """One state change, as logged and as handed to listeners."""

    t: float  # mission clock
    source: str
    dest: str
    trigger: str
    reason: str
    #: The localization after the change (`LOCALIZATION`); "" where the sender had none.
    localization: str = ""

    def line(self) -> str:
        return f"mission: {self.source} -> {self.dest} ({self.reason})"


Listener = Callable[[StateChange], None]


class _Model:
    """What `transitions` binds its triggers and `state` to, so `Mission` keeps a plain,
    typed surface."""

    state: str


class _ResumesCondition:
    """A `Resumes` row's condition: the interrupted task is one of its tasks. Its
    `__name__` is the label the diagram shows."""

    def __init__(self, mission: Mission, spec: Resumes) -> None:
        self.mission = mission
        self.tasks = spec.tasks
        self.__name__ = spec.label

    def __call__(self, event: EventData) -> bool:
        return self.mission.interrupted in self.tasks


class Mission:
    """The RMC mission's state machine (Planning layer). See the module docstring."""

    def __init__(self, executive: Executive, stop_robot: Callable[[], None], *,
                 config: MissionConfig | None = None, context: MissionContext | None = None,
                 owner_name: str = "autonomy") -> None:
        self.executive = executive
        self.config = config or MissionConfig()
        self.context = context or MissionContext()
        self.owner_name = owner_name
        self._stop_robot = stop_robot
        self._listeners: list[Listener] = []
        self._activity: Activity | None = None
        self._now = 0.0
        self._entered_at = 0.0
        self.has_control = False
        self.interrupted: str | None = None  # the run's task to resume after a problem
        self._must_relocalize = False
        self._fixed = False  # a first pose was found
        self._lost = False  # a loss was taken and the pose not found again
        self._relocalize_tries = 0
        self._step_retries = 0
        self._retry_step: str | None = None  # the task whose finish resets the counters
        self._observed_owner: str | None = None
        #: Why a supervisor (the fleet) holds the mission paused; None when it does not.
        self.held: str | None = None
        self._held_pause = False  # the pause is the hold's, not an operator's
        self._pending_fault: str | None = None
        self._out_since: float | None = None
        self._home_since: float | None = None
        self._dock_since: float | None = None
        self.visited: dict[str, int] = {}
        self.last_change: StateChange | None = None
        self._model = _Model()
        self._triggers_of: dict[str, frozenset[str]] = {}  # what each state accepts
        self.machine = Machine(
            model=self._model,
            states=[{"name": s.name, "final": s.name == FINAL} for s in STATES],
            transitions=[self._resolve(row) for row in TRANSITIONS],
            initial=INITIAL,
            queued=True,
            send_event=True,
            auto_transitions=False,
            ignore_invalid_triggers=True,
            before_state_change=[self._leave],
            after_state_change=[self._arrive],
            on_exception=[self._on_exception],
        )

    # -- inputs ------------------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Begin the run at `now`: the time budget starts here."""
        if self.state != INITIAL:
            raise MissionError(f"the mission has already started (state {self.state})")
        missing = self.executive.missing()
        if missing:
            raise MissionError("no activity registered for: " + ", ".join(missing))
        cfg = self.config
        self.context.budget = TimeBudget(now, cfg.duration_s, cfg.end_margin_s)
        self.context.estimates = Estimates(cfg.trip_estimate_s, cfg.dock_deposit_estimate_s,
                                           cfg.min_dig_s, home_s=cfg.trip_estimate_s)
        self._now = now
        self._fire("start", f"run of {cfg.duration_s:g} s")

    def tick(self, now: float, dt: float) -> None:
        """One iteration: the first check that calls for a change makes it (see the module
        docstring for their order); when none does, the current activity ticks."""
        self._now = now
        if self.state in (INITIAL, FINAL):
            return
        try:
            self._step(now, dt)
        except Exception as err:  # an activity's tick; the machine's own are hooked
            self._handle_exception(err, f"{self.state} tick")

    def observe_control(self, owner: str) -> None:
        """The newest `robot:control.owner` (a name, or `none`); acted on at the next tick.

        Another name pauses the mission; `none` ends a pause (only `none`: an answer read
        late could still name us after an operator took over). Feed it from the connection
        the activities command on, so its answers arrive in order with theirs."""
        self._observed_owner = owner

    def hold(self, reason: str) -> None:
        """A supervisor's pause (the fleet's stopPause): acted on at the next tick like an
        operator's takeover (the mission stops commanding and waits in `paused`), and kept
        whoever owns control until `release_hold`."""
        self.held = reason

    def release_hold(self) -> None:
        """End the supervisor's pause: the mission resumes as after a takeover (re-acquire,
        re-localize) unless an operator holds control, whose release it then waits for."""
        self.held = None

    def report_fault(self, reason: str) -> None:
        """A fault seen outside any activity (watchdog tripped, link lost); acted on at the
        next tick: stop, then retry the step (bounded), then wait for the operator."""
        self._pending_fault = reason

    def add_listener(self, listener: Listener) -> None:
        """Called with every `StateChange` (the trace writer, the recorder)."""
        self._listeners.append(listener)

    # -- what it shows -------------------------------------------------------------------------
    @property
    def state(self) -> str:
        return self._model.state

    @property
    def localization(self) -> str:
        """One of `LOCALIZATION`, from the machine's own bookkeeping (not from names)."""
        if self._lost:
            return "lost"
        if self.state in RECOVERY_STATES:
            return "relocalizing"
        return "ok" if self._fixed else "none"

    @property
    def activity(self) -> Activity | None:
        return self._activity

    @property
    def over(self) -> bool:
        return self._model.state == FINAL  # asked after every tick of a simulated run

    @property
    def outcome(self) -> str:
        """SPEC 6.3's outcome so far: `completed`, `waiting_for_operator` or `running`."""
        if self.state == FINAL:
            return "completed"
        if self.state == "waiting_for_operator":
            return "waiting_for_operator"
        return "running"

    # -- conditions (named in the table, drawn in the diagram) ---------------------------------
    def pose_confident(self, event: EventData | None = None) -> bool:
        return self.context.pose_is_confident(self.config.min_pose_confidence)

    def resuming(self, event: EventData | None = None) -> bool:
        return self.interrupted is not None

    def step_retries_left(self, event: EventData | None = None) -> bool:
        return self._step_retries < self.config.max_step_retries

    def must_relocalize(self, event: EventData | None = None) -> bool:
        return self._must_relocalize

    def out_of_tries(self, event: EventData | None = None) -> bool:
        if self._must_relocalize:
            return self._relocalize_tries >= self.config.max_relocalize_tries
        return not self.step_retries_left()

    def time_for_another_cycle(self, event: EventData | None = None) -> bool:
        b, e = self.context.budget, self.context.estimates
        return b.left(self._now) - b.margin_s >= e.cycle_s()

    # -- callbacks named in the table --------------------------------------------------------
    def note_loss(self, event: EventData) -> None:
        source = _source(event)
        if source in RUN:
            self.interrupted = self._retry_step = source
            self.context.localization_losses += 1
        self._must_relocalize = True
        self._lost = True
        self.context.last_problem = _reason_of(event)

    def note_problem(self, event: EventData) -> None:
        source = _source(event)
        if source in RUN:
            self.interrupted = self._retry_step = source
            self.context.faults += 1
        self.context.last_problem = _reason_of(event)

    def note_pause(self, event: EventData) -> None:
        source = _source(event)
        self.has_control = False
        self._observed_owner = None  # only news from after the takeover counts
        if source in RUN:
            self.interrupted = source
        if self.interrupted is not None:
            self._must_relocalize = True  # the operator may have moved it anywhere
        self._reset_tries()  # the operator's turn earns fresh tries

    def count_relocalize(self, event: EventData) -> None:
        self._relocalize_tries += 1

    def count_retry(self, event: EventData) -> None:
        self._step_retries += 1

    # -- the machine's hooks -----------------------------------------------------------------
    def _leave(self, event: EventData) -> None:
        source, trigger = _source(event), event.event.name
        dest = event.transition.dest if event.transition else None
        act, self._activity = self._activity, None
        if act is not None:
            try:
                act.stop()
            except Exception as err:
                log.error("mission: the %s activity's stop raised %s: %s", source,
                          type(err).__name__, err, exc_info=err)
                self._halt()
        if (STATE[source].activity and trigger not in ("finished", "control_taken")
                and dest not in HALTING):
            self._halt()  # interrupted work: nothing it started may go on

    def _arrive(self, event: EventData) -> None:
        source, trigger, dest, now = _source(event), event.event.name, self.state, self._now
        self._entered_at = now
        self.visited[dest] = self.visited.get(dest, 0) + 1
        if source == "acquire_control" and trigger == "finished":
            self.has_control = True
            self._observed_owner = None  # answers from before the acquire are stale
        if trigger == "finished" and source == self._retry_step and dest != "stop":
            self._reset_tries()
        if source == "relocalize" and dest == "resume":
            self._must_relocalize = False
            self._lost = False
            self._fixed = True
        if source == "initial_localization" and trigger == "finished":
            self._fixed = True
        resumed = self.interrupted if source == "resume" else None
        if resumed is not None:
            self.interrupted = None
        self._measure(source, trigger, dest, now)
        change = StateChange(now, source, dest, trigger, self._why(event, resumed),
                             self.localization)
        self.last_change = change
        level = logging.WARNING if dest in ("stop", "paused", "waiting_for_operator") \
            else logging.INFO
        log.log(level, change.line())
        for listener in self._listeners:
            try:
                listener(change)
            except Exception as err:
                log.error("mission: a listener raised %s: %s", type(err).__name__, err,
                          exc_info=err)
        if dest in HALTING:
            self._halt()
        if STATE[dest].activity:
            self._start_activity(dest, now)
        if dest == "resume":
            self._fire("dispatch", f"resume {self.interrupted}")

    def _on_exception(self, event: EventData) -> None:
        where = f"{self.state} (on {event.event.name})"
        err = event.error if event.error is not None else MissionError("unknown error")
        self._handle_exception(err, where)

    # -- inside --------------------------------------------------------------------------------
    def _step(self, now: float, dt: float) -> None:
        if self._check_control():
            return
        budget = self.context.budget
        left = budget.left(now)
        if left <= 0 and self._accepts("time_up"):
            self._fire("time_up", "the run's time is over")
            return
        if self._pending_fault is not None:
            reason, self._pending_fault = self._pending_fault, None
            if self._accepts("fault"):
                self._fire("fault", reason)
                return
            log.info("mission: fault reported in %s, nothing to stop: %s", self.state, reason)
        state = self.state
        if state in DRIVING and not self.pose_confident():
            self._fire("lost", self._confidence_text())
            return
        timeout = self.config.timeout_of(state)
        if timeout is not None and now - self._entered_at >= timeout:
            self._fire("failed", f"no result after {timeout:g} s")
            return
        return_s = self.context.estimates.return_s()
        if state in OUTBOUND and left - budget.margin_s <= return_s:
            kg = self.context.bin_kg
            if kg >= self.config.min_return_load_kg and left >= return_s:
                self._fire("head_home", f"{left:.0f} s left, the return takes about "
                           f"{return_s:.0f} s; {kg:.1f} kg in the bin")
            else:
                self._fire("time_up", f"a last return does not pay: {left:.0f} s left, "
                           f"{return_s:.0f} s needed, {kg:.1f} kg in the bin")
            return
        if self._activity is not None:
            status = self._activity.tick(now, dt)
            if not isinstance(status, Status):
                raise MissionError(f"the {state} activity's tick returned {status!r}, "
                                   "not a Status")
            if status.trigger is not None:
                self._fire(status.trigger, status.reason)

    def _check_control(self) -> bool:
        if self.held is not None:
            if self.state == "paused":
                owner, self._observed_owner = self._observed_owner, None
                if owner is not None:
                    self.context.control_owner = owner
                return True
            if self._accepts("control_taken"):
                self._held_pause = True
                self._halt()  # no operator's acquire stopped it: the hold stops what we run
                self._fire("control_taken", f"held by a supervisor: {self.held}")
                return True
        elif self._held_pause:
            # The hold ended: resume if control is free or still ours; under an operator's
            # control, wait for its release as after any takeover.
            if self.state != "paused":
                self._held_pause = False
            elif self.context.control_owner in (NO_OWNER, self.owner_name):
                self._held_pause = False
                self._fire("control_free", "the supervisor's hold ended")
                return True
        owner, self._observed_owner = self._observed_owner, None
        if owner is None:
            return False
        self.context.control_owner = owner
        state = self.state
        if state == "paused":
            if owner == NO_OWNER:
                self._fire("control_free", "control is free")
                return True
            return False
        if not self._accepts("control_taken"):
            return False
        if owner not in (NO_OWNER, self.owner_name):
            self._fire("control_taken", f"{owner} took control")
            return True
        if owner == NO_OWNER and self.has_control and state != "waiting_for_operator":
            # the backend dropped our control (a reconnect): take it back and re-localize;
            # a robot waiting for its operator keeps waiting for one
            self._fire("control_taken", "control was given up (owner none)")
            return True
        return False

    def _fire(self, trigger: str, reason: str) -> None:
        self._model.trigger(trigger, reason=reason)  # type: ignore[attr-defined]

    def _accepts(self, trigger: str) -> bool:
        state = self.state
        triggers = self._triggers_of.get(state)
        if triggers is None:  # the table is fixed once the machine is built: ask once a state
            triggers = frozenset(self.machine.get_triggers(state))
            self._triggers_of[state] = triggers
        return trigger in triggers

    def _start_activity(self, state: str, now: float) -> None:
        factory = self.executive.factory(state)
        if factory is not None:
            activity = factory()
        elif state == "stop":
            activity = StandStill(self.config.stop_settle_s)
        else:
            raise MissionError(f"no activity registered for {state}")
        self._activity = activity  # before start: a start that raises is still stopped
        activity.start(self.context, now)

    def _halt(self) -> None:
        """Stop the robot, unless an operator holds control (the motion is theirs)."""
        if not self.has_control:
            return
        try:
            self._stop_robot()
        except Exception as err:
            log.critical("mission: could not stop the robot: %s: %s", type(err).__name__, err,
                         exc_info=err)

    def _handle_exception(self, err: BaseException, where: str) -> None:
        log.error("mission: %s raised %s: %s", where, type(err).__name__, err, exc_info=err)
        self._halt()
        if self._accepts("fault"):
            self._fire("fault", f"{type(err).__name__} in {where}: {err}")

    def _reset_tries(self) -> None:
        self._relocalize_tries = self._step_retries = 0
        self._retry_step = None

    def _measure(self, source: str, trigger: str, dest: str, now: float) -> None:
        """Time the legs of a cycle, recoveries included, for the end-of-run decisions."""
        est = self.context.estimates
        if dest == "plan_path_to_dig" and self._out_since is None:
            self._out_since = now
        elif dest == "excavate" and self._out_since is not None:
            est.trip_s = Estimates.blend(est.trip_s, now - self._out_since)
            self._out_since = None
            if not est.home_measured:
                # Until the way home has been driven, it is taken as long as the way out
                # as measured: the guess (`trip_estimate_s`) was 30 s short on a slow
                # layout and sized the first dig for a second cycle that never fitted.
                est.home_s = est.trip_s
        elif dest == "plan_path_home":
            self._out_since = None
            if self._home_since is None:
                self._home_since = now
        elif dest == "dock":
            if self._home_since is not None:
                est.home_s = Estimates.blend(est.home_s, now - self._home_since)
                self._home_since = None
                est.home_measured = True
            if self._dock_since is None:
                self._dock_since = now
        if source == "decouple" and trigger == "finished" and self._dock_since is not None:
            est.dock_deposit_s = Estimates.blend(est.dock_deposit_s, now - self._dock_since)
            self._dock_since = None

    def _confidence_text(self) -> str:
        ctx = self.context
        if ctx.pose is None:
            return "no pose"
        return f"pose confidence {ctx.pose_confidence:.2f} < {self.config.min_pose_confidence:g}"

    def _why(self, event: EventData, resumed: str | None) -> str:
        """The log line's reason: the trigger, what the firer said, and for a conditional
        edge, the condition that chose it."""
        source, trigger, dest = _source(event), event.event.name, self.state
        said = _reason_of(event)
        text = f"{trigger}: {said}" if said and said != trigger else trigger
        if resumed is not None:
            return f"{trigger}: resume {resumed}"
        if trigger == "finished" and dest == "stop":
            return f"{text}; {self._confidence_text()}"
        if dest == "waiting_for_operator" and source == "stop":
            cfg = self.config
            if self._must_relocalize:
                return f"still lost after {cfg.max_relocalize_tries} relocalization tries"
            return (f"still failing after {cfg.max_step_retries} retries "
                    f"({self.context.last_problem})")
        if source == "decouple" and trigger == "finished":
            b, e = self.context.budget, self.context.estimates
            left = b.left(self._now)
            verdict = "time for another cycle" if dest != FINAL else "no time for another cycle"
            return (f"{text}; {verdict}: {left:.0f} s left less a {b.margin_s:g} s margin, "
                    f"a cycle takes about {e.cycle_s():.0f} s")
        return text

    def _resolve(self, row: dict[str, Any]) -> dict[str, Any]:
        """A table row with its names turned into this mission's methods."""
        out = dict(row)
        for key in ("conditions", "unless"):
            if key in row:
                out[key] = [self._condition(c) for c in row[key]]
        if "before" in row:
            if row["before"] not in CALLBACKS:
                raise MissionError(f"the table names an unknown callback {row['before']!r}")
            out["before"] = getattr(self, row["before"])
        return out

    def _condition(self, cond: str | Resumes) -> Callable[[EventData], bool]:
        if isinstance(cond, Resumes):
            return _ResumesCondition(self, cond)
        if cond not in CONDITIONS:
            raise MissionError(f"the table names an unknown condition {cond!r}")
        fn: Callable[[EventData], bool] = getattr(self, cond)
        return fn


def _source(event: EventData) -> str:
    if event.transition is not None:
        return event.transition.source
    return event.state.name


def _reason_of(event: EventData) -> str:
    return str(event.kwargs.get("reason", ""))

