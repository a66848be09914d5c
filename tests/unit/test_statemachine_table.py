"""The mission's table, as the machine builds it: its invariants, its configuration, the
diagram on its documentation page, and that the package stays apart from the backend."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from collections import deque
from pathlib import Path

import pytest
from transitions import Machine
from transitions.core import Condition

from ramp.autonomy.config import MISSION_FIELDS
from ramp.errors import ConfigError
from ramp.statemachine import Executive, Mission, MissionConfig
from ramp.statemachine.__main__ import main
from ramp.statemachine.diagram import condition_label, edges, mermaid, states_table
from ramp.statemachine.table import (
    ACTIVITY_STATES,
    DRIVING,
    FINAL,
    GROUPS,
    INITIAL,
    RESUME_AT,
    RUN,
    STATE,
    STATES,
    TRANSITIONS,
)

REPO = Path(__file__).resolve().parents[2]
STATUS_TRIGGERS = {"finished", "failed", "lost", "fault", "control_taken"}


@pytest.fixture(scope="module")
def machine() -> Machine:
    return Mission(Executive(), lambda: None).machine


def _arrows(machine: Machine) -> set[tuple[str, str, str, str]]:
    """(source, dest, trigger, guard) of every transition of the machine."""
    return {(e.source, e.dest, e.triggers[0], e.guard) for e in edges(machine)}


def _graph(machine: Machine) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {name: set() for name in STATE}
    for source, dest, _, _ in _arrows(machine):
        out[source].add(dest)
    return out


def _reach(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = {start}, deque([start])
    while todo:
        for nxt in graph[todo.popleft()] - seen:
            seen.add(nxt)
            todo.append(nxt)
    return seen


# -- invariants --------------------------------------------------------------------------------
def test_the_machine_is_queued_hooks_exceptions_and_has_only_the_tables_transitions(
        machine: Machine) -> None:
    m = machine
    assert m.has_queue and m.on_exception
    assert list(m.states) == [s.name for s in STATES]
    # no to_<state> shortcuts: the only ways in are the table's rows
    assert len(edges(m)) == len(TRANSITIONS)
    assert not any(t.startswith("to_") for t in m.events)


def test_every_transition_into_a_driving_state_needs_a_confident_pose_and_has_a_twin(
        machine: Machine) -> None:
    arrows = _arrows(machine)
    into_driving = [a for a in arrows if a[1] in DRIVING]
    assert len(into_driving) >= len(DRIVING)
    for source, _dest, trigger, guard in into_driving:
        assert guard.split(", ")[-1] == "pose_confident"
        twin_guard = guard.replace("pose_confident", "not pose_confident")
        assert (source, "stop", trigger, twin_guard) in arrows


def test_every_working_state_answers_every_status(machine: Machine) -> None:
    for state in ACTIVITY_STATES:
        assert set(machine.get_triggers(state)) >= STATUS_TRIGGERS, state


def test_every_task_of_the_run_says_where_it_resumes_and_resumes_there(machine: Machine) -> None:
    assert set(RESUME_AT) == set(RUN)
    arrows = _arrows(machine)
    for task, target in RESUME_AT.items():
        assert target in RUN
        assert any(s == "resume" and d == target and task in g for s, d, _, g in arrows), task


def test_every_state_is_reachable_and_every_state_can_reach_the_end(machine: Machine) -> None:
    graph = _graph(machine)
    assert _reach(graph, INITIAL) == set(STATE)
    for state in STATE:
        assert FINAL in _reach(graph, state), state


def test_the_end_of_the_run_leaves_every_state_but_a_robot_waiting_for_its_operator(
        machine: Machine) -> None:
    ends = {s for s, d, t, _ in _arrows(machine) if t == "time_up" and d == FINAL}
    assert ends == set(STATE) - {INITIAL, "resume", "waiting_for_operator", FINAL}


def test_an_operator_can_take_over_from_every_state_the_mission_commands_in(
        machine: Machine) -> None:
    takers = {s for s, d, t, _ in _arrows(machine) if t == "control_taken"}
    assert takers == set(ACTIVITY_STATES) | {"waiting_for_operator"}
    assert all(d == "paused" for s, d, t, _ in _arrows(machine) if t == "control_taken")


# -- configuration ------------------------------------------------------------------------------
def test_the_mission_config_and_autonomy_yaml_fields_agree() -> None:
    defaults = MissionConfig()
    for name, value in vars(defaults).items():
        if name == "timeouts_s":
            continue
        assert name in MISSION_FIELDS, name
        assert MISSION_FIELDS[name].default == value, name


def test_config_reads_tunables_and_state_timeouts() -> None:
    cfg = MissionConfig.from_mapping({"duration_s": 300.0, "max_step_retries": 5.0,
                                      "timeout_excavate_s": 120, "scan_step_deg": 2.5})
    assert cfg.duration_s == 300.0 and cfg.max_step_retries == 5
    assert cfg.timeout_of("excavate") == 120.0
    assert cfg.timeout_of("dock") == STATE["dock"].timeout_s
    assert cfg.timeout_of("paused") is None


@pytest.mark.parametrize(("key", "value", "message"), [
    ("timeout_dig_s", 5, "mission.timeout_dig_s: no state named 'dig' has a timeout"),
    ("timeout_paused_s", 5, "no state named 'paused' has a timeout"),
    ("timeout_dock_s", 0, "mission.timeout_dock_s: 0 is not a time in s"),
])
def test_config_names_the_key_of_a_bad_timeout(key: str, value: float, message: str) -> None:
    with pytest.raises(ConfigError, match=re.escape(message)):
        MissionConfig.from_mapping({key: value})


# -- the diagram ---------------------------------------------------------------------------------
#: The page that shows the machine (the README only links to it).
PAGE = REPO / "docs" / "autonomy" / "state-machine.md"


def _section() -> str:
    """The page up to its first second-level heading: the diagram and the table of states."""
    text = PAGE.read_text(encoding="utf-8")
    end = text.find("\n## ")
    return text if end < 0 else text[:end]


def test_the_docs_show_the_diagram_and_the_states_the_machine_draws(
        machine: Machine) -> None:
    section = _section()
    block = re.search(r"```mermaid\n(.*?)```", section, re.S)
    assert block is not None, f"no mermaid block at the top of {PAGE.name}"
    assert block.group(1) == mermaid(machine)
    table = states_table()
    assert table in section, f"run `python -m ramp.statemachine --states` into {PAGE.name}"


def test_the_diagram_draws_every_transition_once(machine: Machine) -> None:
    drawn: set[tuple[str, str, str, str]] = set()
    for line in mermaid(machine).splitlines():
        m = re.fullmatch(r"\s*(\w+) --> (\w+) : ([\w /]+?)(?: \[(.*)\])?", line)
        if m is None:
            continue
        source, dest, triggers, guard = m.groups()
        sources = [s.name for s in STATES if s.group == source] if source in GROUPS \
            else [source]
        for s in sources:
            for trigger in triggers.split(" / "):
                key = (s, dest, trigger, guard or "")
                assert key not in drawn, key
                drawn.add(key)
    assert drawn == _arrows(machine)


def test_the_diagram_puts_the_run_in_a_box_and_the_choice_as_a_choice(machine: Machine) -> None:
    text = mermaid(machine)
    assert text.startswith("stateDiagram-v2\n    [*] --> idle\n")
    assert "    state resume <<choice>>\n" in text
    assert '    state "the run, thesis figure 5.35" as run {\n' in text
    assert "    run --> stop : lost / fault / failed\n" in text
    assert text.endswith("    done --> [*]\n")


def test_conditions_are_labelled_by_name() -> None:
    assert condition_label(Condition("pose_confident", target=False)) == "not pose_confident"
    assert condition_label(Condition(Mission.pose_confident)) == "pose_confident"


def test_the_command_prints_the_diagram_and_the_table(machine: Machine,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--mermaid"]) == 0
    assert capsys.readouterr().out == mermaid(machine)
    assert main(["--states"]) == 0
    assert capsys.readouterr().out == states_table()
    with pytest.raises(SystemExit):
        main([])


# -- isolation -------------------------------------------------------------------------------------
def test_the_state_machine_does_not_import_the_backend() -> None:
    code = textwrap.dedent("""\
        import sys
        import ramp.statemachine, ramp.statemachine.__main__, ramp.statemachine.diagram
        banned = ("ramp.layers", "ramp.functional", "ramp.hal", "ramp.server",
                  "ramp.supervisor", "ramp.config", "ramp.sim", "ramp.simulation")
        bad = sorted(m for m in sys.modules if m.split(".")[0] == "firmware_like"
                     or any(m == b or m.startswith(b + ".") for b in banned))
        print(bad)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=REPO)
    assert out.stdout.strip() == "[]"
