"""Interlocks (SPEC 11) over MCP on the simulated MARTE: each action, latch and reset, fail
closed, what robot.get and describe show, and what the flight recorder hears. Inputs are
injected with the `sim` module (SPEC 12), as an acceptance test would."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from ramp.runtime.observers import Observer
from tests.harness import MARTE_YAML, SimHarness, value
from tests.harness import TestClient as Client

#: MARTE's wiring without its shipped rules: these tests bring their own.
WIRING = MARTE_YAML.split("\ninterlocks:")[0] + "\n"
RULES = """\
interlocks:
  - name: chain_needs_ladder_down
    when: "ble:lift.pos > 0.5"
    refuse: ["ble:chain.vel"]
  - name: bumper
    when: "base:l_button.press == 1 or base:r_button.press == 1"
    stop: ["base:*"]
    latch: true
  - name: ladder_down_slow
    when: "ble:lift.pos < 0.2"
    limit: {"base:base.drive": 30, "base:*_wheel.vel": 30}
  - name: heavy_bin_lift
    when: "ble:load.kg > 30"
    limit: {"ble:lift.*": 20}
"""


class Events(Observer):
    def __init__(self) -> None:
        self.seen: list[tuple[str, bool, str]] = []

    def interlock(self, t: float, name: str, active: bool, why: str) -> None:
        self.seen.append((name, active, why))


@pytest.fixture
def events() -> Events:
    return Events()


@pytest.fixture
def h(events: Events) -> Iterator[SimHarness]:
    harness = SimHarness(WIRING + RULES, observer=events)
    yield harness
    harness.close()


def active(c: Client) -> str:
    return value(c.ask("robot:robot.get=()"), "robot:interlock.active")


def wheels(c: Client) -> list[int]:
    got = c.ask("base:base.get=()")
    return [int(value(got, f"base:{w}_wheel.vel")) for w in ("lf", "lb", "rf", "rb")]


def lift_at(h: SimHarness, c: Client, pos: float) -> None:
    """The lift's pot reads `pos` from the next tick on; a rule it clears is released 0.1 s
    later."""
    assert c.ask(f"sim:input.set=(ble,lift_pot,{pos})") == ""
    h.advance(0.12)


def test_robot_get_and_describe_show_the_rules(h: SimHarness) -> None:
    c = h.connect()
    d = c.ask("robot:robot.describe=()")
    for name in ("chain_needs_ladder_down", "bumper", "ladder_down_slow", "heavy_bin_lift"):
        assert f"robot:interlock.rule=({name},warning)" in d
    assert "robot:interlock.property=(active,name)" in d
    assert "robot:interlock.function=(reset,name)" in d
    assert "robot:interlock.kind=(reset,state)" in d
    # The lift rests at 0, retracted: the ladder is down, and only that rule holds.
    assert active(c) == "ladder_down_slow"
    lift_at(h, c, 0.3)
    assert active(c) == "none"


def test_refuse_answers_interlocked_and_stops_what_runs_there(
        h: SimHarness, events: Events) -> None:
    c = h.connect()
    lift_at(h, c, 0.3)
    assert c.ask("ble:chain.vel=(60)") == ""
    h.advance(0.05)
    assert value(c.ask("ble:ble.get=()"), "ble:chain.vel") == "60"
    lift_at(h, c, 0.7)  # the bin rises past 0.5: within that one tick the chain stops
    assert value(c.ask("ble:ble.get=()"), "ble:chain.vel") == "0"
    assert h.world.duty("ble.chain_left") == 0.0
    assert c.ask("ble:chain.vel=(60)") == \
        "ble:chain.error=(interlocked,chain_needs_ladder_down is active)"
    # Stops are never refused (a speed of 0 is one); other motion of the module is not
    # guarded.
    assert c.ask("ble:chain.vel=(0)ble:ble.stop=()robot:robot.stop=()") == ""
    assert c.ask("ble:lift.vel=(10)") == ""
    assert active(c) == "chain_needs_ladder_down"
    # The order of SPEC 2: parameters and ownership are checked first.
    assert c.ask("ble:chain.vel=(600)").startswith("ble:chain.error=(bad_params,")
    other = h.connect()
    assert c.ask("robot:control.acquire=(op)") == ""
    assert other.ask("ble:chain.vel=(60)").startswith("ble:chain.error=(not_owner,")
    lift_at(h, c, 0.3)
    assert c.ask("ble:chain.vel=(60)") == ""
    assert ("chain_needs_ladder_down", True, "active: ble:lift.pos > 0.5") in events.seen
    assert ("chain_needs_ladder_down", False, "released") in events.seen


def test_a_request_sees_what_the_message_changed_before_it(h: SimHarness) -> None:
    """A rule over a commanded value (a get row that a request changes) is evaluated on the
    request, not only in the tick."""
    h2 = SimHarness(WIRING + """\
interlocks:
  - {name: not_while_digging, when: "ble:chain.vel != 0", refuse: ["base:base.drive"]}
""")
    try:
        c = h2.connect()
        assert c.ask("ble:chain.vel=(40)base:base.drive=(20,0)") == \
            "base:base.error=(interlocked,not_while_digging is active)"
        assert wheels(c) == [0, 0, 0, 0]
    finally:
        h2.close()


def test_stop_stops_the_devices_within_one_tick_and_refuses_while_active(
        h: SimHarness) -> None:
    c = h.connect()
    lift_at(h, c, 0.3)
    assert c.ask("base:base.drive=(50,0)") == ""
    h.advance(0.05)
    assert wheels(c) == [50, 50, 50, 50]
    assert c.ask("sim:input.set=(base,l_button,1)") == ""
    for _ in range(10):  # the button's reading changes once its debounce is over
        h.advance(0.01)
        if value(c.ask("base:base.get=()"), "base:l_button.press") == "1":
            break
    h.advance(0.01)  # one tick
    assert wheels(c) == [0, 0, 0, 0]
    assert active(c) == "bumper"
    h.advance(0.01)  # the Sabertooth emulator has read the zeros off the wire
    assert h.world.duty("base.lf_wheel") == 0.0
    assert c.ask("base:base.drive=(50,0)") == "base:base.error=(interlocked,bumper is active)"
    assert c.ask("base:rf_wheel.vel=(5)") == "base:rf_wheel.error=(interlocked,bumper is active)"
    assert c.ask("base:base.drive=(0,45)base:rf_wheel.vel=(0)") == ""  # stops
    assert c.ask("base:base.stop=()") == ""
    assert c.ask("base:user_led.on=(1)") == ""  # not motion: never guarded


def test_a_latched_rule_stays_until_reset_and_reset_is_refused_while_it_holds(
        h: SimHarness, events: Events) -> None:
    c = h.connect()
    lift_at(h, c, 0.3)
    assert c.ask("sim:input.set=(base,r_button,1)") == ""
    h.advance(0.05)
    assert active(c) == "bumper"
    assert c.ask("robot:interlock.reset=(bumper)") == (
        "robot:interlock.error=(interlocked,bumper: its condition still holds; reset once it "
        "has cleared)")
    assert c.ask("sim:input.clear=(base,r_button)") == ""
    h.advance(0.15)
    assert active(c) == "bumper"  # latched: the button is free, the rule is not
    assert c.ask("base:base.drive=(20,0)") == \
        "base:base.error=(interlocked,bumper is latched until robot:interlock.reset)"
    assert c.ask("robot:interlock.reset=(nope)") == (
        "robot:interlock.error=(bad_params,no interlock nope; rules: chain_needs_ladder_down "
        "bumper ladder_down_slow heavy_bin_lift)")
    # Kind state: owner-only while someone owns control.
    owner = h.connect()
    assert owner.ask("robot:control.acquire=(op)") == ""
    assert c.ask("robot:interlock.reset=(bumper)").startswith(
        "robot:interlock.error=(not_owner,")
    assert owner.ask("robot:interlock.reset=(bumper)") == ""
    assert active(c) == "none"
    assert owner.ask("base:base.drive=(20,0)") == ""
    assert owner.ask("robot:interlock.reset=(bumper)") == ""  # nothing latched: nothing to do
    latched = [e for e in events.seen if e[0] == "bumper"]
    assert latched[0][1] and "latched until robot:interlock.reset=(bumper)" in latched[0][2]
    assert latched[-1] == ("bumper", False, "released")


def test_limit_clamps_new_requests_and_brings_running_motion_down(h: SimHarness) -> None:
    c = h.connect()
    lift_at(h, c, 0.3)
    assert c.ask("base:base.drive=(80,0)") == ""
    h.advance(0.05)
    assert wheels(c) == [80, 80, 80, 80]
    lift_at(h, c, 0.1)  # the ladder comes down: within one tick the drive is at 30
    assert wheels(c) == [30, 30, 30, 30]
    assert c.ask("base:base.drive=(-90,0)") == ""  # answered empty, run at -30
    h.advance(0.02)
    assert wheels(c) == [-30, -30, -30, -30]
    assert c.ask("base:lf_wheel.vel=(100)base:rb_wheel.vel=(-10)") == ""
    assert wheels(c) == [30, -30, -30, -10]
    assert c.ask("base:base.drive=(20,90)") == ""  # within the limit: as asked
    assert wheels(c) == [20, 20, -20, -20]
    lift_at(h, c, 0.3)
    assert c.ask("base:base.drive=(80,0)") == ""
    assert wheels(c) == [80, 80, 80, 80]


def test_a_limit_over_a_drive_with_no_reading_of_its_own_brings_it_down(
        h: SimHarness) -> None:
    h2 = SimHarness(WIRING + """\
interlocks:
  - {name: drive_only, when: "ble:lift.pos < 0.2", limit: {"base:base.drive": 25}}
""")
    try:
        c = h2.connect()
        lift_at(h2, c, 0.3)
        assert c.ask("base:base.drive=(80,30)") == ""
        h2.advance(0.02)
        lift_at(h2, c, 0.1)
        got = wheels(c)
        assert max(abs(v) for v in got) == 25, got
        # SPEC 11: a pattern covers the devices its function moves, so a limit on
        # base.drive holds a wheel commanded on its own too.
        assert c.ask("base:base.drive=(80,0)base:lf_wheel.vel=(70)") == ""
        h2.advance(0.05)
        assert wheels(c) == [25, 25, 25, 25]
    finally:
        h2.close()


def test_a_limit_refuses_motion_without_a_speed_and_leaves_other_motion_alone(
        h: SimHarness) -> None:
    c = h.connect()
    lift_at(h, c, 0.3)
    assert c.ask("sim:input.set=(ble,load_cell,35)") == ""
    h.advance(0.02)
    assert "heavy_bin_lift" in active(c)
    assert c.ask("ble:lift.vel=(100)ble:ble.get=()").startswith("ble:lift.vel=(20)")
    assert c.ask("ble:lift.pos=(1.0)") == \
        "ble:lift.error=(interlocked,heavy_bin_lift limits ble:lift and pos has no speed)"
    assert c.ask("ble:lift.extend=()").startswith("ble:lift.error=(interlocked,")
    assert c.ask("ble:chain.vel=(90)") == ""


def test_fail_closed_a_rule_whose_property_cannot_be_read_is_active(
        h: SimHarness, events: Events) -> None:
    c = h.connect()
    lift_at(h, c, 0.3)
    assert active(c) == "none"
    assert c.ask("sim:bus.unplug=(ble_io)") == ""  # the lift's pot board vanishes
    h.advance(0.2)
    assert value(c.ask("robot:robot.get=()"), "robot:ble.state") == "fault"
    # Every rule reading the BLE: its lift, its load.
    assert active(c) == "chain_needs_ladder_down,ladder_down_slow,heavy_bin_lift"
    assert c.ask("base:base.drive=(80,0)") == ""
    h.advance(0.02)
    assert wheels(c) == [30, 30, 30, 30]
    assert ("ladder_down_slow", True, "active (fail closed): ble:lift.pos cannot be read") \
        in events.seen
    assert c.ask("base:base.stop=()sim:bus.plug=(ble_io)") == ""
    h.advance(2.5)  # re-attached within about a second
    assert value(c.ask("robot:robot.get=()"), "robot:ble.state") == "ok"
    assert active(c) == "none"


def test_a_rule_is_released_once_clear_for_a_tenth_of_a_second_so_it_never_flaps(
        h: SimHarness, events: Events) -> None:
    c = h.connect()
    lift_at(h, c, 0.3)
    for _ in range(20):  # the pot hovers about the threshold, tick after tick
        assert c.ask("sim:input.set=(ble,lift_pot,0.51)") == ""
        h.advance(0.01)
        assert c.ask("sim:input.set=(ble,lift_pot,0.49)") == ""
        h.advance(0.01)
    assert [e for e in events.seen if e[0] == "chain_needs_ladder_down"] == [
        ("chain_needs_ladder_down", True, "active: ble:lift.pos > 0.5")]
    h.advance(0.05)
    assert "chain_needs_ladder_down" in active(c)
    h.advance(0.06)
    assert "chain_needs_ladder_down" not in active(c)
    assert events.seen[-1] == ("chain_needs_ladder_down", False, "released")


def test_a_jammed_lift_stops_the_base_through_its_latched_stall_row() -> None:
    """`sim:lift.jam` stalls the lift; the BLE's own stall detection latches `lift.stalled`,
    and a rule over that row stops the base until the fault is acknowledged."""
    h = SimHarness(WIRING + """\
interlocks:
  - {name: lift_stalled, when: "ble:lift.stalled == 1", stop: ["base:*", "ble:chain.vel"]}
""")
    try:
        c = h.connect()
        assert c.ask("sim:lift.jam=(1)ble:lift.vel=(60)base:base.drive=(40,0)") == ""
        for _ in range(30):  # the stall guard needs 1.5 s without progress
            h.advance(0.1)
            assert c.ask("") == ""
            if active(c) == "lift_stalled":
                break
        assert active(c) == "lift_stalled"
        assert value(c.ask("ble:ble.get=()"), "ble:lift.stalled") == "1"
        assert wheels(c) == [0, 0, 0, 0]
        assert c.ask("base:base.drive=(40,0)") == \
            "base:base.error=(interlocked,lift_stalled is active)"
    finally:
        h.close()


def test_activations_and_releases_are_flight_recorder_events(tmp_path: Path) -> None:
    from ramp.recorder import Recorder, RecorderConfig
    from ramp.recorder.reading import Recording
    from ramp.recorder.summary import Summary, format_report

    rec = Recorder(RecorderConfig(str(tmp_path / "rec")))
    h = SimHarness(WIRING + RULES, recorder=rec)
    try:
        c = h.connect()
        lift_at(h, c, 0.7)
        lift_at(h, c, 0.3)
        assert c.ask("ble:chain.vel=(20)") == ""
        lift_at(h, c, 0.8)
        h.advance(0.2)
    finally:
        h.close()
    msgs = list(Recording(sorted((tmp_path / "rec").glob("*.mcap"))))
    events = [m.data["text"] for m in msgs
              if m.topic == "/robot/events" and m.data["kind"] == "interlock"]
    assert events == ["ladder_down_slow active: ble:lift.pos < 0.2",
                      "chain_needs_ladder_down active: ble:lift.pos > 0.5",
                      "ladder_down_slow released",
                      "chain_needs_ladder_down released",
                      "chain_needs_ladder_down active: ble:lift.pos > 0.5"]
    summary = Summary()
    for m in msgs:
        summary.add(m)
    report = summary.report()
    assert report["interlocks"] == {"ladder_down_slow": 1, "chain_needs_ladder_down": 2}
    assert "interlocked" not in report["error_responses"]
    assert "interlocks ladder_down_slow 1 activation, chain_needs_ladder_down 2 activations" \
        in format_report(report)


def test_a_latched_rule_does_not_latch_on_an_unreadable_property(h: SimHarness) -> None:
    c = h.connect()
    lift_at(h, c, 0.3)
    assert c.ask("sim:bus.unplug=(sbc_io)") == ""  # the buttons' board
    h.advance(0.2)
    assert "bumper" in active(c)
    assert c.ask("robot:interlock.reset=(bumper)") == ""  # not latched: nothing to reset
    assert c.ask("sim:bus.plug=(sbc_io)") == ""
    h.advance(2.5)
    assert "bumper" not in active(c)


def test_a_limit_engaging_is_a_note_a_refusal_is_a_warning(
        h: SimHarness, caplog: pytest.LogCaptureFixture) -> None:
    """A limit engaging is routine (MARTE slows every time it digs) and is logged at INFO;
    a rule that refuses or stops motion is a WARNING an operator should see."""
    import logging

    c = h.connect()
    lift_at(h, c, 0.3)  # ladder_down_slow released
    with caplog.at_level(logging.INFO, logger="ramp"):
        caplog.clear()
        lift_at(h, c, 0.1)  # the limit engages
        lift_at(h, c, 0.7)  # the refusal engages
    levels = {r.getMessage().split()[1]: r.levelno for r in caplog.records
              if r.getMessage().startswith("interlock ") and " active" in r.getMessage()}
    assert levels == {"ladder_down_slow": logging.INFO,
                      "chain_needs_ladder_down": logging.WARNING}, levels
