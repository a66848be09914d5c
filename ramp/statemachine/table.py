"""The mission's states and transitions, as data (thesis figure 5.35 plus SPEC 6.3's recovery).

Nothing here runs: `ramp.statemachine.mission.Mission` builds a `transitions` machine from
these tables, `ramp.statemachine.diagram` draws them, and the tests check their invariants.
To change the mission's flow, change the tables; the machine, the diagram on
docs/autonomy/state-machine.md and
the checks follow.

- `STATES`: every state with what it does, whether an activity drives it, whether it may
  move the robot across the ground (then it needs a confident pose), whether entering it
  stops the robot, and its timeout.
- `TRANSITIONS`: rows `{trigger, source, dest, conditions, unless, before}` in the order the
  machine tries them (the first whose conditions hold wins). Conditions and `before`
  callbacks are names of `Mission` methods; `Resumes` rows leave the `resume` choice.
- `RESUME_AT`: where an interrupted task goes on after a recovery or a pause. A drive goes
  back to its planning state (the robot has moved, or stood still while lost).

The drive guard is applied to the rows, not written by hand: every transition into a
driving state gets the condition `pose_confident`, and a twin right after it that goes to
`stop` when the pose is not confident. So the machine cannot enter a driving state while
lost, whoever wrote the row.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class StateSpec:
    name: str
    does: str  # one line for the table on docs/autonomy/state-machine.md
    group: str = ""  # "run" (thesis figure 5.35), "recovery", "control" or ""
    activity: bool = True  # an activity from the Executive drives it
    drives: bool = False  # may move the robot across the ground: needs a confident pose
    halts: bool = False  # entering it stops the robot (when the mission holds control)
    choice: bool = False  # passed through at once (a decision, drawn as a choice)
    timeout_s: float | None = None  # `failed` after this long in the state


STATES: tuple[StateSpec, ...] = (
    StateSpec("idle", "waits for `Mission.start(now)`", activity=False),
    StateSpec("acquire_control", "acquires control as `autonomy` once nobody else holds it",
              "control", timeout_s=10.0),
    # -- the run: thesis figure 5.35 ------------------------------------------------------
    StateSpec("initial_localization", "finds the pose from a level scan of the walls; the "
              "start box and heading break the arena's symmetry", "run", timeout_s=60.0),
    StateSpec("prepare_for_scan", "drives, inside the start region, to where the 3D scan "
              "sees the obstacle region (facing +x) and localizes there", "run", drives=True,
              timeout_s=60.0),
    StateSpec("scan_for_obstacles", "tilts the LIDAR through its angles, one 2D scan at "
              "each, merged into a 3D scan", "run", timeout_s=60.0),
    StateSpec("detect_obstacles", "finds rocks and craters in the 3D scan and builds the "
              "planner from them", "run", timeout_s=30.0),
    StateSpec("plan_path_to_dig", "picks the next digging spot that does not repeat (or "
              "the interrupted one) and plans the way there", "run", timeout_s=30.0),
    StateSpec("cross_to_dig", "follows the plan across the obstacle area, localizing "
              "between scans", "run", drives=True, timeout_s=180.0),
    StateSpec("excavate", "lowers the ladder, runs the chain and creeps forward until the "
              "target load or time", "run", drives=True, timeout_s=300.0),
    StateSpec("plan_path_home", "plans back to the collector: its approach, then a "
              "straight reverse", "run", timeout_s=30.0),
    StateSpec("cross_home", "follows the plan home, the last leg backwards onto the "
              "collector wall", "run", drives=True, timeout_s=180.0),
    StateSpec("dock", "finishes on the docking buttons `l_button` and `r_button`", "run",
              drives=True, timeout_s=60.0),
    StateSpec("deposit", "raises the bin and waits for `load.kg` to fall", "run",
              timeout_s=90.0),
    StateSpec("decouple", "lowers the bin and drives clear of the collector", "run",
              drives=True, timeout_s=60.0),
    # -- recovery (SPEC 6.3) ----------------------------------------------------------------
    StateSpec("stop", "stops the robot and waits until it stands still", "recovery",
              halts=True, timeout_s=15.0),
    StateSpec("relevel", "levels the LIDAR from the scan itself (the walls are the "
              "horizon)", "recovery", timeout_s=30.0),
    StateSpec("rescan", "takes a fresh level 2D scan", "recovery", timeout_s=30.0),
    StateSpec("relocalize", "matches the scan to the walls, the AHRS yaw breaking the "
              "symmetry", "recovery", timeout_s=30.0),
    StateSpec("resume", "chooses where the interrupted task goes on (`RESUME_AT`)",
              activity=False, choice=True),
    # -- the operator and the end -----------------------------------------------------------
    StateSpec("paused", "an operator has control: commands nothing until control is free",
              "control", activity=False),
    StateSpec("waiting_for_operator", "stopped, still lost or still failing: waits for an "
              "operator to take over", "control", activity=False, halts=True),
    StateSpec("done", "the run is over; stopped", activity=False, halts=True),
)

STATE: dict[str, StateSpec] = {s.name: s for s in STATES}
INITIAL = "idle"
FINAL = "done"
RUN = tuple(s.name for s in STATES if s.group == "run")
RECOVERY = tuple(s.name for s in STATES if s.group == "recovery")
DRIVING = frozenset(s.name for s in STATES if s.drives)
HALTING = frozenset(s.name for s in STATES if s.halts)
ACTIVITY_STATES = tuple(s.name for s in STATES if s.activity)
#: Where the decision "head home now?" is taken every tick near the end of the run.
OUTBOUND = ("plan_path_to_dig", "cross_to_dig", "excavate")
#: Groups drawn as one box in the diagram, by `StateSpec.group` (an edge that leaves every
#: member for the same place is drawn once, from the box).
GROUPS: dict[str, str] = {"run": "the run, thesis figure 5.35"}

#: The cycle of figure 5.35; after `decouple` it starts again at `plan_path_to_dig`.
CYCLE = (
    ("initial_localization", "prepare_for_scan"),
    ("prepare_for_scan", "scan_for_obstacles"),
    ("scan_for_obstacles", "detect_obstacles"),
    ("detect_obstacles", "plan_path_to_dig"),
    ("plan_path_to_dig", "cross_to_dig"),
    ("cross_to_dig", "excavate"),
    ("excavate", "plan_path_home"),
    ("plan_path_home", "cross_home"),
    ("cross_home", "dock"),
    ("dock", "deposit"),
    ("deposit", "decouple"),
)

RESUME_AT: dict[str, str] = {
    "initial_localization": "prepare_for_scan",  # relocalized is localized
    "prepare_for_scan": "prepare_for_scan",
    "scan_for_obstacles": "prepare_for_scan",  # level again, then the whole scan
    "detect_obstacles": "detect_obstacles",
    "plan_path_to_dig": "plan_path_to_dig",
    "cross_to_dig": "plan_path_to_dig",
    "excavate": "plan_path_to_dig",  # back to `ctx.dig_spot`, wherever the robot is now
    "plan_path_home": "plan_path_home",
    "cross_home": "plan_path_home",
    "dock": "plan_path_home",
    "deposit": "deposit",
    "decouple": "decouple",
}

#: Every trigger. `finished`, `failed`, `lost`, `fault` and `control_taken` come from
#: activity statuses (`Status.trigger`); the others from the machine's own checks.
TRIGGERS = ("start", "finished", "failed", "lost", "fault", "control_taken", "control_free",
            "head_home", "time_up", "dispatch")

PROBLEMS = ("lost", "fault", "failed")


@dataclass(frozen=True)
class Resumes:
    """Condition of a row leaving `resume`: the interrupted task is one of `tasks`."""

    tasks: tuple[str, ...]

    @property
    def label(self) -> str:
        return "from " + ", ".join(self.tasks)


Condition = str | Resumes
Row = dict[str, Any]


def _rows(triggers: str | Iterable[str], sources: str | Iterable[str], dest: str,
          conditions: Condition | list[Condition] | None = None, unless: str | None = None,
          before: str | None = None) -> list[Row]:
    trig = [triggers] if isinstance(triggers, str) else list(triggers)
    src = [sources] if isinstance(sources, str) else list(sources)
    conds = [] if conditions is None else (
        conditions if isinstance(conditions, list) else [conditions])
    out: list[Row] = []
    for t in trig:
        for s in src:
            row: Row = {"trigger": t, "source": s, "dest": dest}
            if conds:
                row["conditions"] = list(conds)
            if unless:
                row["unless"] = [unless]
            if before:
                row["before"] = before
            out.append(row)
    return out


def _resume_rows() -> list[Row]:
    targets: dict[str, list[str]] = {}
    for task, target in RESUME_AT.items():
        targets.setdefault(target, []).append(task)
    out: list[Row] = []
    for target, tasks in targets.items():
        out += _rows("dispatch", "resume", target, Resumes(tuple(tasks)))
    return out


def _drive_guard(rows: list[Row]) -> list[Row]:
    """Guard every row into a driving state, and add its twin that goes to `stop`."""
    out: list[Row] = []
    for row in rows:
        if row["dest"] not in DRIVING:
            out.append(row)
            continue
        guarded = dict(row, conditions=[*row.get("conditions", []), "pose_confident"])
        twin: Row = {k: v for k, v in row.items() if k != "before"}
        twin["dest"] = "stop"
        twin["unless"] = [*row.get("unless", []), "pose_confident"]
        twin["before"] = "note_loss"
        out += [guarded, twin]
    return out


_BEFORE_GUARD: list[Row] = [
    *_rows("start", "idle", "acquire_control"),
    *_rows("finished", "acquire_control", "relevel", "resuming", before="count_relocalize"),
    *_rows("finished", "acquire_control", "initial_localization"),
    *_rows(PROBLEMS, "acquire_control", "acquire_control", "step_retries_left",
           before="count_retry"),
    *_rows(PROBLEMS, "acquire_control", "waiting_for_operator"),
    # figure 5.35, then round again while there is time
    *[r for a, b in CYCLE for r in _rows("finished", a, b)],
    *_rows("finished", "decouple", "plan_path_to_dig", "time_for_another_cycle"),
    *_rows("finished", "decouple", "done"),
    *_rows("head_home", OUTBOUND, "plan_path_home"),
    # a problem in the run: stop, then recover
    *_rows("lost", RUN, "stop", before="note_loss"),
    *_rows(("fault", "failed"), RUN, "stop", before="note_problem"),
    *_rows("finished", "stop", "waiting_for_operator", "out_of_tries"),
    *_rows("finished", "stop", "relevel", "must_relocalize", before="count_relocalize"),
    *_rows("finished", "stop", "resume", before="count_retry"),
    *_rows(PROBLEMS, "stop", "waiting_for_operator"),
    # a latched fault (a stalled lift): only an operator may clear it; no retry, no reset
    *_rows("needs_operator", ("acquire_control", *RUN, *RECOVERY, "stop"),
           "waiting_for_operator", before="note_problem"),
    *_rows("finished", "relevel", "rescan"),
    *_rows("finished", "rescan", "relocalize"),
    *_rows("finished", "relocalize", "resume", "pose_confident"),
    *_rows("finished", "relocalize", "stop", unless="pose_confident", before="note_loss"),
    *_rows(PROBLEMS, ("relevel", "rescan", "relocalize"), "stop", before="note_loss"),
    *_resume_rows(),
    # the operator (SPEC 6.3)
    *_rows("control_taken", ("acquire_control", *RUN, *RECOVERY, "waiting_for_operator"),
           "paused", before="note_pause"),
    *_rows("control_free", "paused", "acquire_control"),
    # the end of the run
    *_rows("time_up", ("acquire_control", *RUN, *RECOVERY, "paused"), "done"),
]

TRANSITIONS: tuple[Row, ...] = tuple(_drive_guard(_BEFORE_GUARD))
