"""The RMC mission's state machine: the Planning layer of the autonomy (thesis 5.3.4, figure
5.35; SPEC 6.3).

The machine decides *what* to do next; activities (Executive layer, `ramp.autonomy.executive`)
decide *how*. Part of the removable autonomy: it imports `transitions` and `ramp.errors`,
never the backend, and `ramp.autonomy`'s planning types for type checking only (the
executive imports the machine, so the machine does not import the autonomy back).

The flow (`table.py`; drawn by `python -m ramp.statemachine --mermaid`):

    idle -> acquire_control -> initial_localization -> prepare_for_scan ->
    scan_for_obstacles -> detect_obstacles -> plan_path_to_dig -> cross_to_dig -> excavate ->
    plan_path_home -> cross_home -> dock -> deposit -> decouple -> plan_path_to_dig -> ...
    -> done

- **End of the run.** After `decouple` a new cycle starts only if the time left, less
  `end_margin_s`, covers a whole cycle (`Estimates.cycle_s`). While outbound
  (`plan_path_to_dig`, `cross_to_dig`, `excavate`) the machine checks every tick whether the
  time left, less the margin, still covers the return (`Estimates.return_s`); when it does
  not, it goes home (`head_home`) if that pays - at least `min_return_load_kg` in the bin and
  the return fits in the time left - else it ends (`time_up` -> `done`). At the end of the
  time every state but `waiting_for_operator` goes to `done`.
- **Recovery.** `lost` -> `stop` -> `relevel` -> `rescan` -> `relocalize` (up to
  `max_relocalize_tries` passes) -> `resume` -> where the interrupted task goes on
  (`table.RESUME_AT`: a drive is planned again), or `waiting_for_operator`. A `fault` or
  `failed` -> `stop` -> `resume` the step (up to `max_step_retries` times), then
  `waiting_for_operator`. A driving state (`prepare_for_scan`, `cross_to_dig`, `excavate`,
  `cross_home`, `dock`, `decouple`) is never entered, nor stayed in, without a confident
  pose.
- **Operator.** An operator's takeover (`Status.operator`, or `observe_control` with another
  owner) -> `paused`: nothing more is commanded, not even a stop. When control is free
  again -> `acquire_control` -> `relevel` -> `rescan` -> `relocalize` -> `resume`.

Plugging in the executive:

    from ramp.statemachine import Executive, Mission, MissionConfig, Status

    class FollowPlan:                        # any object with start / tick / stop
        def __init__(self, link): ...
        def start(self, ctx, now):           # ctx: MissionContext (ctx.plan, ctx.pose ...)
            self.ctx = ctx; ...
        def tick(self, now, dt):             # one step, never blocks
            ...
            return Status.running()          # or done() / failed(why) / lost(why) /
                                             # operator(why) / fault(why) /
                                             # Status.from_mcp_error(code, detail)
        def stop(self):                      # stop working; send no command
            ...

    executive = Executive({
        "acquire_control": lambda: AcquireControl(link, "autonomy"),
        "initial_localization": lambda: Localize(link, perception, initial=True),
        "cross_to_dig": lambda: FollowPlan(link),
        ...                                  # every name in table.ACTIVITY_STATES but `stop`
    })
    mission = Mission(executive, stop_robot=link.stop_all,   # sends robot:robot.stop=()
                      config=MissionConfig.from_mapping(autonomy_cfg.mission))
    mission.add_listener(trace.on_state_change)
    mission.start(clock.now())
    scheduler.add_task("mission", 10.0, mission.tick)   # after the localizer's task
    # and from the link, every robot.get answer / every problem seen outside activities:
    mission.observe_control(owner)        # robot:control.owner, "none" when free
    mission.report_fault("watchdog tripped")

What each working state's activity must do is in `table.STATES` (and the table on
docs/autonomy/state-machine.md);
the contract every activity keeps is in `activity.py`.
"""

from ramp.statemachine.activity import Activity, ActivityFactory, Executive, StandStill
from ramp.statemachine.context import Estimates, MissionContext, TimeBudget
from ramp.statemachine.mission import Mission, MissionError, StateChange
from ramp.statemachine.settings import MissionConfig
from ramp.statemachine.status import Status, StatusKind

__all__ = [
    "Activity", "ActivityFactory", "Estimates", "Executive", "Mission", "MissionConfig",
    "MissionContext", "MissionError", "StandStill", "StateChange", "Status", "StatusKind",
    "TimeBudget",
]
