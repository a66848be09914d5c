"""The Executive layer's side of the mission: activities, and the registry that names them.

The machine (Planning layer, thesis 5.3.4) decides *what* to do; each working state's
activity (Executive layer) decides *how*, with the Functional layer's pieces (localizer,
gimbal, planner, path follower, the MCP link). An activity is any object with

    start(ctx: MissionContext, now: float) -> None   # the state was entered
    tick(now: float, dt: float) -> Status            # one step; never blocks
    stop() -> None                                   # the state is left, for any reason

The rules an activity follows:

- `start` and `tick` never block and never sleep: send a request, return `running`, look
  for the answer at the next tick. Time is the `now` they are given.
- Return `Status.done()` only once the job is complete and the robot is as the next state
  expects it (a drive ends with the wheels stopped).
- Map MCP error answers with `Status.from_mcp_error(code, detail)`: `not_owner` means an
  operator took control (the machine pauses), anything else is a fault (the machine stops
  the robot and retries the step a bounded number of times).
- `stop` ends the activity's own work (drop the plan, stop feeding the watchdog). It sends
  no command to the robot: when the robot must stop, the machine calls its own `stop_robot`
  - and it does not after an operator took control, since the motion is then the
  operator's. `stop` may be called more than once.
- Write what the next states need into the `MissionContext` (pose, obstacles, plan, load).

An `Executive` maps state names to factories: a fresh activity is made each time its state
is entered, so an activity never has to reset itself:

    executive = Executive({
        "initial_localization": lambda: Localize(link, localizer, initial=True),
        "cross_to_dig": lambda: FollowPlan(link, follower_config),
        ...
    })

Every state in `ramp.statemachine.table.ACTIVITY_STATES` needs one, except `stop`, which
falls back to `StandStill` (wait `stop_settle_s` after the machine's stop).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol, runtime_checkable

from ramp.statemachine.context import MissionContext
from ramp.statemachine.status import Status
from ramp.statemachine.table import ACTIVITY_STATES


@runtime_checkable
class Activity(Protocol):
    """What drives one working state (see the module's docstring for the rules)."""

    def start(self, ctx: MissionContext, now: float) -> None: ...

    def tick(self, now: float, dt: float) -> Status: ...

    def stop(self) -> None: ...


ActivityFactory = Callable[[], Activity]

#: States that work without a registered activity, and what they use instead.
BUILT_IN = ("stop",)


class Executive:
    """State name -> activity factory. Data, not a class hierarchy: the mission engineer
    registers one factory per working state."""

    def __init__(self, factories: Mapping[str, ActivityFactory] | None = None) -> None:
        self._factories: dict[str, ActivityFactory] = {}
        for state, factory in (factories or {}).items():
            self.register(state, factory)

    def register(self, state: str, factory: ActivityFactory) -> None:
        if state not in ACTIVITY_STATES:
            raise ValueError(f"no working state named {state!r} "
                             f"(working states: {', '.join(ACTIVITY_STATES)})")
        if not callable(factory):
            raise TypeError(f"the activity of {state!r} must be a factory (a callable "
                            f"returning an activity), got {factory!r}")
        self._factories[state] = factory

    @property
    def states(self) -> tuple[str, ...]:
        return tuple(self._factories)

    def missing(self) -> list[str]:
        """Working states with no activity and no built-in one."""
        return [s for s in ACTIVITY_STATES if s not in self._factories and s not in BUILT_IN]

    def factory(self, state: str) -> ActivityFactory | None:
        return self._factories.get(state)


class StandStill:
    """The built-in `stop` activity: the machine has sent its stop; wait `settle_s` for the
    robot to come to rest. An executive that can see the wheels register a better one."""

    def __init__(self, settle_s: float) -> None:
        self.settle_s = settle_s
        self._until = 0.0

    def start(self, ctx: MissionContext, now: float) -> None:
        self._until = now + self.settle_s

    def tick(self, now: float, dt: float) -> Status:
        return Status.done("standing still") if now >= self._until else Status.running()

    def stop(self) -> None:
        pass
