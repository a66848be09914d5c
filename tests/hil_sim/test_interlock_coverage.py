"""Interlocks cover the actuator, not the spelling, and never bring motion back (SPEC 11;
issue 33 items 4 and 5): a limit lowers only what runs now, a pattern covers every function
that moves the devices it names, a refuse/stop entry may forbid one direction only, and
`describe` carries each rule's severity and message. Over MCP on the simulated robots."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.harness import MARTE_YAML, SCOUT_YAML, SimHarness, value
from tests.harness import TestClient as Client

WIRING = MARTE_YAML.split("\ninterlocks:")[0] + "\n"


def wheels(c: Client) -> list[int]:
    got = c.ask("base:base.get=()")
    return [int(value(got, f"base:{w}_wheel.vel")) for w in ("lf", "lb", "rf", "rb")]


def active(c: Client) -> str:
    return value(c.ask("robot:robot.get=()"), "robot:interlock.active")


@pytest.fixture
def marte() -> Iterator[SimHarness]:
    h = SimHarness(MARTE_YAML)  # the shipped rules: digging_creep holds while digging
    yield h
    h.close()


def with_rules(rules: str) -> SimHarness:
    return SimHarness(WIRING + "interlocks:\n" + rules)


# -- a limit never brings motion back (33.4) ------------------------------------------------

def test_a_takeover_stop_is_not_undone_by_digging_creep(marte: SimHarness) -> None:
    """The issue's reproduction: the takeover stops the wheels; the chain then starts
    `digging_creep` (the lift rests at 0), whose limit used to re-send the last drive at
    10 % with nobody having commanded the base since the stop."""
    c = marte.connect()
    assert c.ask("base:base.drive=(60,0)robot:control.acquire=(x)ble:chain.vel=(5)") == ""
    for _ in range(10):
        marte.advance(0.02)
        assert wheels(c) == [0, 0, 0, 0]
    assert "digging_creep" in active(c)
    assert c.ask("base:base.drive=(60,0)") == ""  # a new request: creeps, as it should
    assert wheels(c) == [10, 10, 10, 10]


def test_a_watchdog_trip_is_not_undone_by_a_limit(marte: SimHarness) -> None:
    """Two clients: A drives and falls silent; the trip stops everything; B then runs the
    chain (digging_creep engages) and keeps talking: the base stays still."""
    a, b = marte.connect(), marte.connect()
    assert a.ask("robot:watchdog.timeout=(0.2)base:base.drive=(60,0)") == ""
    marte.advance(0.1)
    assert b.ask("") == ""
    marte.advance(0.15)  # A silent past its timeout
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.state") == "tripped"
    assert b.ask("ble:chain.vel=(5)") == ""
    for _ in range(10):
        marte.advance(0.02)
        assert wheels(b) == [0, 0, 0, 0]
    assert "digging_creep" in active(b)


def test_a_stop_rule_then_a_limit_never_restarts_the_base() -> None:
    h = with_rules("""\
  - {name: bumper, when: "base:l_button.press == 1", stop: ["base:*"]}
  - {name: creep, when: "ble:chain.vel != 0", limit: {"base:base.drive": 10}}
""")
    try:
        c = h.connect()
        assert c.ask("base:base.drive=(60,30)sim:input.set=(base,l_button,1)") == ""
        h.advance(0.1)
        assert "bumper" in active(c)
        assert wheels(c) == [0, 0, 0, 0]
        assert c.ask("sim:input.clear=(base,l_button)ble:chain.vel=(5)") == ""
        for _ in range(15):
            h.advance(0.02)
            assert wheels(c) == [0, 0, 0, 0]
    finally:
        h.close()


def test_a_limit_still_brings_running_drive_down_keeping_its_direction(
        marte: SimHarness) -> None:
    c = marte.connect()
    assert c.ask("base:base.drive=(60,30)ble:chain.vel=(5)") == ""
    marte.advance(0.05)
    got = wheels(c)
    assert max(abs(v) for v in got) == 10 and got[0] > got[2] > 0, got


# -- the actuator, not the spelling (33.5) --------------------------------------------------

def test_a_limit_on_lift_vel_covers_extend_retract_and_pos() -> None:
    h = with_rules("""\
  - {name: slow_lift, when: "ble:load.kg > 30", limit: {"ble:lift.vel": 20}}
""")
    try:
        c = h.connect()
        assert c.ask("sim:input.set=(ble,load_cell,35)") == ""
        h.advance(0.05)
        assert active(c) == "slow_lift"
        for req in ("ble:lift.extend=()", "ble:lift.retract=()", "ble:lift.pos=(0.8)"):
            assert c.ask(req).startswith("ble:lift.error=(interlocked,slow_lift"), req
        assert c.ask("ble:lift.vel=(100)ble:ble.get=()").startswith("ble:lift.vel=(20)")
        assert c.ask("ble:chain.vel=(90)") == ""  # another actuator
    finally:
        h.close()


def test_an_extend_running_when_the_limit_engages_is_brought_down() -> None:
    h = with_rules("""\
  - {name: slow_lift, when: "ble:load.kg > 30", limit: {"ble:lift.vel": 20}}
""")
    try:
        c = h.connect()
        assert c.ask("ble:lift.extend=()") == ""
        h.advance(0.05)
        assert value(c.ask("ble:ble.get=()"), "ble:lift.vel") == "100"
        assert c.ask("sim:input.set=(ble,load_cell,35)") == ""
        h.advance(0.05)
        assert value(c.ask("ble:ble.get=()"), "ble:lift.vel") == "20"
    finally:
        h.close()


def test_a_refuse_on_one_wheel_covers_the_drive_that_moves_it() -> None:
    h = with_rules("""\
  - {name: lf_off, when: "ble:lift.pos > 0.5", refuse: ["base:lf_wheel.vel"]}
""")
    try:
        c = h.connect()
        assert c.ask("base:base.drive=(50,0)") == ""
        assert c.ask("sim:input.set=(ble,lift_pot,0.8)") == ""
        h.advance(0.05)
        assert active(c) == "lf_off"
        assert wheels(c)[0] == 0  # the covered wheel stopped when the rule engaged
        assert c.ask("base:base.drive=(50,0)").startswith(
            "base:base.error=(interlocked,lf_off")
        assert c.ask("base:base.drive=(0,0)") == ""  # a stop is never refused
        assert c.ask("base:rf_wheel.vel=(30)") == ""  # a wheel the rule does not cover
        assert wheels(c) == [0, 0, 30, 0]
    finally:
        h.close()


def test_a_stop_on_the_drive_covers_each_wheel() -> None:
    h = with_rules("""\
  - {name: no_drive, when: "ble:lift.pos > 0.5", stop: ["base:base.drive"]}
""")
    try:
        c = h.connect()
        assert c.ask("base:lf_wheel.vel=(40)base:rb_wheel.vel=(-40)") == ""
        assert c.ask("sim:input.set=(ble,lift_pot,0.8)") == ""
        h.advance(0.05)
        assert active(c) == "no_drive"
        assert wheels(c) == [0, 0, 0, 0]
        for w in ("lf", "lb", "rf", "rb"):
            assert c.ask(f"base:{w}_wheel.vel=(30)").startswith(
                f"base:{w}_wheel.error=(interlocked,no_drive"), w
            assert c.ask(f"base:{w}_wheel.vel=(0)") == ""
    finally:
        h.close()


def test_check_explain_lists_what_each_rule_covers() -> None:
    from ramp.config import check_config  # noqa: PLC0415 - only this test needs it
    from ramp.config.interlocks import explain  # noqa: PLC0415

    config, errors = check_config("ramp.yaml")
    assert not errors and config is not None
    text = "\n".join(explain(config.interlocks, config.modules))
    assert "digging_creep (info)" in text
    assert "base:base.drive to 10 % covers base:base.drive, base:lf_wheel.vel, " \
           "base:lb_wheel.vel, base:rf_wheel.vel, base:rb_wheel.vel" in text


# -- direction: Scout backs away from a pressed bumper --------------------------------------

@pytest.fixture
def scout() -> Iterator[SimHarness]:
    h = SimHarness(SCOUT_YAML, marte=False)
    yield h
    h.close()


def scout_wheels(c: Client) -> tuple[int, int]:
    got = c.ask("base:base.get=()")
    return int(value(got, "base:left_wheel.vel")), int(value(got, "base:right_wheel.vel"))


def test_scout_backs_away_from_a_pressed_bumper_then_resets(scout: SimHarness) -> None:
    c = scout.connect()
    assert c.ask("base:base.drive=(50,0)sim:input.set=(base,bumper_left,1)") == ""
    scout.advance(0.1)
    assert "bumper" in active(c)
    assert scout_wheels(c) == (0, 0)  # it was driving into it: stopped
    for forward in ("base:base.drive=(20,0)", "base:base.drive=(-20,180)",
                    "base:base.drive=(30,90)",  # a spin turns one wheel forward
                    "base:left_wheel.vel=(10)", "base:right_wheel.vel=(10)"):
        got = c.ask(forward)
        assert "error=(interlocked,bumper" in got and "forward motion refused" in got, forward
    assert c.ask("robot:interlock.reset=(bumper)").startswith(
        "robot:interlock.error=(interlocked")  # still pressed
    assert c.ask("base:base.drive=(30,180)") == ""  # backing away works
    assert scout_wheels(c) == (-30, -30)
    assert c.ask("base:base.drive=(30,160)") == ""  # backing away while turning
    assert c.ask("base:left_wheel.vel=(-10)") == ""
    assert c.ask("sim:input.clear=(base,bumper_left)") == ""
    scout.advance(0.2)
    assert c.ask("base:base.drive=(20,0)").startswith("base:base.error=(interlocked,bumper")
    assert c.ask("robot:interlock.reset=(bumper)") == ""
    scout.advance(0.05)
    assert c.ask("base:base.drive=(20,0)") == ""
    assert scout_wheels(c) == (20, 20)


def test_scout_reversing_into_a_bumper_press_keeps_reversing(scout: SimHarness) -> None:
    c = scout.connect()
    assert c.ask("base:base.drive=(-40,0)sim:input.set=(base,bumper_right,1)") == ""
    scout.advance(0.1)
    assert "bumper" in active(c)
    assert scout_wheels(c) == (-40, -40)


# -- severity and message in describe (35.1) ------------------------------------------------

def test_describe_carries_severity_and_message(marte: SimHarness) -> None:
    d = marte.connect().ask("robot:robot.describe=()")
    assert "robot:interlock.rule=(digging_creep,info)" in d
    assert "robot:interlock.rule=(chain_needs_ladder_down,warning)" in d
    assert "robot:interlock.message=(digging_creep,Digging: the base creeps at 10 % " in d
