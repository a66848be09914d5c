"""`interlocks:` in ramp.yaml (SPEC 11): checked against the module tables with file:line:key
errors, in `ramp check` and `ramp run` alike."""

from __future__ import annotations

from pathlib import Path

import pytest

from ramp.cli import main
from ramp.config import parse_config
from ramp.layers.robot_distribution.condition import Compare
from tests.harness import MARTE_YAML

#: MARTE's wiring without its shipped rules: these tests bring their own.
WIRING = MARTE_YAML.split("\ninterlocks:")[0] + "\n"
N = WIRING.count("\n")  # the rules below start on line N + 1


def errors_of(rules: str) -> list[str]:
    cfg, errors = parse_config(WIRING + rules, "ramp.yaml")
    assert cfg is None, "expected errors"
    return [str(e) for e in errors]


def test_the_spec_example_rules_load_as_data() -> None:
    cfg, errors = parse_config(WIRING + """\
interlocks:
  - name: ladder_down_slow
    when: "ble:lift.pos < 0.2"
    limit: {"base:base.drive": 30, "base:*_wheel.vel": 30}
  - name: chain_needs_ladder_down
    when: "0.5 < ble:lift.pos"
    refuse: ["ble:chain.vel"]
  - name: docked-stop
    when: "base:l_button.press == 1 or base:r_button.press == 1"
    stop: ["base:*"]
    latch: true
""", "ramp.yaml")
    assert errors == [] and cfg is not None
    slow, chain, docked = cfg.interlocks
    assert slow.name == "ladder_down_slow" and slow.action == "limit" and not slow.latch
    assert slow.patterns == (("base:base.drive", 30), ("base:*_wheel.vel", 30))
    assert chain.when == Compare("ble:lift.pos", ">", 0.5)
    assert chain.patterns == (("ble:chain.vel", None),)
    assert docked.action == "stop" and docked.latch and docked.line == N + 8


def test_every_rule_problem_is_named_by_line_and_key() -> None:
    errs = errors_of("""\
interlocks:
  - name: bad name!
    when: "ble:lift.pos < 0.2 and (base:l_button.press == 1"
    refuse: ["ble:chain.vel"]
  - name: unknowns
    when: "ble:lift.pox > 0.5 or arm:shoulder.pos > 3 or base:lx_button.press == 1"
    stop: ["base:foo.vel", "ble:chain.spin", "ble:load.tare", "ble:chain.vel()"]
  - name: limits
    when: "ble:lift.pos > 0.5"
    limit: {"ble:lift.pos": 30, "ble:chain.vel": 101, "ble:lift.vel": -1}
    latch: 1
  - name: limits
    when: ble:lift.pos > 0.5
    refuse: ["ble:chain.vel"]
    stop: ["ble:lift.vel"]
  - name: nothing
    when: 3
    refuse: []
    colour: blue
""")
    at = {e.split(": ", 2)[0] + ": " + e.split(": ", 2)[1]: e for e in errs}
    expected_keys = [
        (N + 2, "interlocks[0].name"), (N + 3, "interlocks[0].when"),
        (N + 6, "interlocks[1].when"), (N + 7, "interlocks[1].stop"),
        (N + 10, "interlocks[2].limit"), (N + 11, "interlocks[2].latch"),
        (N + 12, "interlocks[3].name"), (N + 12, "interlocks[3]"),
        (N + 17, "interlocks[4].when"), (N + 18, "interlocks[4].refuse"),
        (N + 19, "interlocks[4].colour"),
    ]
    for line, key in expected_keys:
        assert f"ramp.yaml:{line}: {key}" in at, (line, key, errs)
    text = "\n".join(errs)
    assert "bad name!' is not a rule name" in text
    assert "expected ')' to close the '(' at column 24" in text
    assert "ble:lift.pox: ble:lift has no property pox (it has: pos, stalled, vel)" in text
    assert "arm:shoulder.pos: no module arm (modules: base, ble)" in text
    assert "base:lx_button.press: module base has no get property on a device lx_button" in text
    assert "base:foo.vel: no device foo in base" in text
    assert "ble:chain.spin: no function spin (motion functions there: chain.vel)" in text
    assert "ble:load.tare: no motion function on ble:load (motion devices: chain, lift)" in text
    assert "'ble:chain.vel()' is not a pattern" in text
    assert "limit: ble:lift.pos has no speed to limit" in text
    assert "got an empty list" in text
    assert "101 is not a speed limit; expected an integer % in 0-100" in text
    assert "-1 is not a speed limit" in text
    assert "1 is not true or false" in text
    assert "limits is already the name of interlocks[2]" in text
    assert "expected exactly one action" in text and "(given: refuse, stop)" in text
    assert "expected a condition as text (quote it), got an integer" in text
    assert "unknown key (expected: name, when, refuse, stop, limit, latch, severity, " \
           "message)" in text


def test_a_section_that_is_not_a_list_of_rules_is_an_error() -> None:
    assert errors_of("interlocks: {name: x}\n") == [
        f"ramp.yaml:{N + 1}: interlocks: expected a list of rules (- name: ..., when: ..., one "
        "of refuse/stop/limit), got a mapping"]
    assert errors_of("interlocks: [3]\n")[0].startswith(
        f"ramp.yaml:{N + 1}: interlocks[0]: expected a rule")


def test_a_limit_pattern_with_a_star_may_also_match_functions_without_a_speed() -> None:
    cfg, errors = parse_config(WIRING + """\
interlocks:
  - {name: lift_slow, when: "ble:load.kg > 30", limit: {"ble:lift.*": 20}}
""", "ramp.yaml")
    assert errors == [] and cfg is not None


def test_a_plain_string_is_one_pattern() -> None:
    cfg, errors = parse_config(WIRING + """\
interlocks:
  - {name: one, when: "ble:load.kg > 30", refuse: "ble:chain.vel"}
""", "ramp.yaml")
    assert errors == [] and cfg is not None
    assert cfg.interlocks[0].patterns == (("ble:chain.vel", None),)


def test_ramp_check_counts_the_rules_of_marte(capsys: pytest.CaptureFixture[str]) -> None:
    from tests.harness import REPO

    assert main(["check", str(REPO / "ramp.yaml")]) == 0
    assert capsys.readouterr().out.strip().endswith(
        "ramp.yaml: ok (5 buses, 2 modules: base, ble; 3 interlocks)")


@pytest.mark.parametrize("command", ["check", "run"])
def test_ramp_check_and_ramp_run_refuse_a_bad_rule_with_exit_2(
        command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "ramp.yaml"
    path.write_text(WIRING + """\
interlocks:
  - name: typo
    when: "ble:lift.pos < 0.2"
    refuse: ["ble:chian.vel"]
""")
    argv = ["check", str(path)] if command == "check" else ["run", "--sim", "--config",
                                                              str(path), "--port", "0"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"{path}:{N + 4}: interlocks[0].refuse: ble:chian.vel: no device chian in ble" in err
    assert "Traceback" not in err


def test_a_rule_may_not_be_named_none() -> None:
    errs = errors_of("""\
interlocks:
  - {name: none, when: "ble:load.kg > 30", refuse: ["ble:chain.vel"]}
  - {name: NONE, when: "ble:load.kg > 30", refuse: ["ble:chain.vel"]}
""")
    assert errs[0].startswith(f"ramp.yaml:{N + 2}: interlocks[0].name: none is reserved")
    assert errs[1].startswith(f"ramp.yaml:{N + 3}: interlocks[1].name: NONE is reserved")


def test_severity_message_and_directions_load_as_data() -> None:
    cfg, errors = parse_config(WIRING + """\
interlocks:
  - name: creep
    when: "ble:chain.vel != 0"
    limit: {"base:base.drive": 10}
    severity: info
    message: "Digging: the base creeps"
  - name: bump
    when: "base:l_button.press == 1"
    stop: [{"base:*": forward}, "ble:chain.vel"]
    severity: error
  - {name: back, when: "base:r_button.press == 1", refuse: {"base:base.drive": reverse}}
""", "ramp.yaml")
    assert errors == [] and cfg is not None
    creep, bump, back = cfg.interlocks
    assert (creep.severity, creep.message, creep.directions) == (
        "info", "Digging: the base creeps", ())
    assert (bump.severity, bump.message) == ("error", "")
    assert bump.patterns == (("base:*", None), ("ble:chain.vel", None))
    assert bump.directions == (1, 0)
    assert back.severity == "warning" and back.directions == (-1,)


def test_bad_severity_message_or_direction_is_named_by_line_and_key() -> None:
    errs = "\n".join(errors_of("""\
interlocks:
  - {name: a, when: "ble:load.kg > 30", refuse: ["ble:chain.vel"], severity: fatal}
  - {name: b, when: "ble:load.kg > 30", refuse: ["ble:chain.vel"], message: "a, b"}
  - {name: c, when: "ble:load.kg > 30", refuse: ["ble:chain.vel"], message: "x)"}
  - {name: d, when: "ble:load.kg > 30", refuse: [{"base:*": backwards}]}
  - {name: e, when: "ble:load.kg > 30", limit: {"base:*": forward}}
  - {name: f, when: "ble:load.kg > 30", refuse: ["ble:chain.vel"], message: 3}
"""))
    assert f"ramp.yaml:{N + 2}: interlocks[0].severity: 'fatal' is not a severity" in errs
    assert f"ramp.yaml:{N + 3}: interlocks[1].message: 'a, b': a message is one line" in errs
    assert f"ramp.yaml:{N + 4}: interlocks[2].message: 'x)'" in errs
    assert f"ramp.yaml:{N + 5}: interlocks[3].refuse: {{'base:*': 'backwards'}}: a " \
           "one-direction entry is {PATTERN: forward} or {PATTERN: reverse}" in errs
    assert "interlocks[4].limit: 'forward' is not a speed limit" in errs
    assert f"ramp.yaml:{N + 7}: interlocks[5].message: expected the operator's advice" in errs


def test_more_rules_than_the_cap_is_one_clear_error() -> None:
    from ramp.layers.robot_distribution.interlocks import MAX_RULES

    rules = "".join(f"  - {{name: r{i}, when: \"ble:load.kg > {i}\", refuse: [ble:chain.vel]}}\n"
                    for i in range(MAX_RULES + 1))
    errs = errors_of("interlocks:\n" + rules)
    assert errs == [f"ramp.yaml:{N + 1}: interlocks: {MAX_RULES + 1} rules; at most "
                    f"{MAX_RULES} (every request and tick may evaluate them: merge rules that "
                    "share a condition)"]


def test_ramp_check_explain_lists_what_each_rule_covers(
        capsys: pytest.CaptureFixture[str]) -> None:
    from tests.harness import REPO

    assert main(["check", "--explain", str(REPO / "examples/robots/scout.yaml")]) == 0
    out = capsys.readouterr().out
    assert "bumper (error, latched): stop while base:bumper_left.press == 1 or " \
           "base:bumper_right.press == 1" in out
    assert "  base:* (forward only) covers base:base.drive, base:left_wheel.vel, " \
           "base:right_wheel.vel" in out
    assert "  base:base.drive to 30 % covers base:base.drive, base:left_wheel.vel, " \
           "base:right_wheel.vel" in out
