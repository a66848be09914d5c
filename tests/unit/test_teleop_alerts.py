"""The console's alerts (SPEC 7.1): what raises each, its severity and advice, the order."""

from __future__ import annotations

from ramp.mcp.describe import InterlockInfo, build_catalog
from ramp.mcp.protocol import parse_response_line
from ramp.teleop.alerts import ConsoleAlerts, Inputs, alert_view, latch_flags, raised


def ids(i: Inputs) -> dict[str, str]:
    return {a.id: a.severity for a in raised(i)}


def view(**kw: object) -> dict[str, object]:
    base: dict[str, object] = {"connected": True, "stale": False, "state": "cross_to_dig",
                               "reason": "", "numbers": {"pose_confidence": 0.9}}
    base.update(kw)
    return base


def test_a_healthy_robot_and_mission_raise_nothing() -> None:
    i = Inputs(values={"robot:watchdog.state": "armed", "base:battery.volt": "20.5",
                       "robot:interlock.active": "none"}, states={"base": "ok"},
               batteries=("base:battery.volt",), autonomy=view())
    assert raised(i) == []


def test_robot_side_alerts_say_what_happened_and_what_to_do() -> None:
    i = Inputs(values={"robot:watchdog.state": "tripped", "base:battery.volt": "17.4",
                       "ble:lift.stalled": "1", "robot:interlock.active": "ladder_down_slow"},
               states={"base": "ok", "ble": "fault"}, errors={"ble": "fault: bus gone"},
               batteries=("base:battery.volt",), latches=("ble:lift.stalled",))
    alerts = {a.id: a for a in raised(i)}
    assert {k: a.severity for k, a in alerts.items()} == {
        "module:ble": "error", "latched:ble:lift": "error",
        "interlock:ladder_down_slow": "warning",
        "watchdog": "warning", "battery:base:battery.volt": "warning"}
    latched = alerts["latched:ble:lift"]
    assert latched.reset == "ble:lift" and "ble:lift.reset=()" in latched.text
    assert "ladder_down_slow" in alerts["interlock:ladder_down_slow"].title
    assert "10 %" in alerts["battery:base:battery.volt"].text
    assert alert_view(latched, 1.0)["takeover"]
    assert not alert_view(alerts["watchdog"], 1.0)["takeover"]


def test_a_lost_robot_link_is_an_error() -> None:
    assert ids(Inputs(robot_reachable=False, robot_detail="refused")) == {"robot-link": "error"}


def test_the_autonomy_lost_waiting_or_unsure_raises_its_alerts() -> None:
    assert ids(Inputs(autonomy=view(state="relocalize", localization="lost"))) == {
        "localization": "error"}
    assert ids(Inputs(autonomy=view(state="stop", localization="lost"))) == {
        "localization": "error"}
    # Re-localizing after a hand-back is not being lost, and nothing to act on: no alert
    # (the autonomy panel shows the state, Events the change).
    assert ids(Inputs(autonomy=view(state="relevel", localization="relocalizing",
                                    numbers={"pose_confidence": 0.1}))) == {}
    # The enum decides, not the state's name or the reason's wording.
    assert ids(Inputs(autonomy=view(state="cross_to_dig", reason="lost the walls",
                                    localization="ok"))) == {}
    waiting = raised(Inputs(autonomy=view(state="waiting_for_operator",
                                          reason="still lost after 3 relocalization tries")))
    assert [(a.id, a.severity) for a in waiting] == [("mission-waiting", "error")]
    assert "still lost after 3" in waiting[0].text and "Hand back" in waiting[0].text
    assert ids(Inputs(autonomy=view(numbers={"pose_confidence": 0.3},
                                    localization="ok"))) == {"confidence": "warning"}
    # Before the first fix a zero confidence is no alarm.
    assert ids(Inputs(autonomy=view(state="initial_localization", localization="none",
                                    numbers={"pose_confidence": 0.0}))) == {}
    paused = raised(Inputs(values={"robot:control.owner": "ann"}, operator="ann",
                           autonomy=view(state="paused")))
    assert [(a.id, a.severity) for a in paused] == [("mission-paused", "info")]
    assert "ann has control (you)" in paused[0].text


def test_an_unreachable_or_stale_view_is_a_warning_and_no_autonomy_means_no_view_alert() -> None:
    assert ids(Inputs(autonomy=view(connected=False, detail="refused"))) == {
        "autonomy-view": "warning"}
    assert ids(Inputs(autonomy=view(stale=True))) == {"autonomy-view": "warning"}
    assert ids(Inputs(autonomy=None)) == {}


def test_the_book_orders_by_severity_then_recency_and_keeps_first_raised_times() -> None:
    book = ConsoleAlerts()
    i = Inputs(values={"robot:watchdog.state": "tripped"})
    assert book.update(raised(i), 1.0)
    i.states = {"ble": "fault"}
    assert book.update(raised(i), 2.0)
    i.robot_reachable = False
    assert book.update(raised(i), 3.0)
    assert [a["id"] for a in book.view()] == ["robot-link", "module:ble", "watchdog"]
    assert [a["since"] for a in book.view()] == [3.0, 2.0, 1.0]
    assert not book.update(raised(i), 4.0)  # nothing new: nothing to send
    i.states = {"ble": "ok"}
    assert book.update(raised(i), 5.0)
    assert [a["id"] for a in book.view()] == ["robot-link", "watchdog"]
    assert book.view()[1]["since"] == 1.0


def rules(**severities: str) -> dict[str, InterlockInfo]:
    return {n: InterlockInfo(n, s) for n, s in severities.items()}


def test_an_info_interlock_is_no_alert_and_warning_or_error_ones_say_what_to_do() -> None:
    """Issue 35: digging_creep shaping every dig was a yellow banner for the whole dig."""
    values = {"robot:interlock.active": "digging_creep"}
    assert ids(Inputs(values=values, interlocks=rules(digging_creep="info"))) == {}
    values = {"robot:interlock.active": "digging_creep,bumper,arm_out"}
    book = {"digging_creep": InterlockInfo("digging_creep", "info"),
            "bumper": InterlockInfo("bumper", "error", "Back away from what the bumper hit"),
            "arm_out": InterlockInfo("arm_out", "warning")}
    alerts = {a.id: a for a in raised(Inputs(values=values, interlocks=book))}
    assert {k: a.severity for k, a in alerts.items()} == {
        "interlock:bumper": "error", "interlock:arm_out": "warning"}
    assert alerts["interlock:bumper"].text.startswith("Back away from what the bumper hit.")
    assert alert_view(alerts["interlock:bumper"], 0.0)["takeover"]
    # No rule speaks of the lift unless it says so itself.
    assert "lift" not in alerts["interlock:arm_out"].text
    assert "robot:interlock.reset=(arm_out)" in alerts["interlock:arm_out"].text


def test_describe_gives_each_rule_its_severity_and_message_old_robots_mean_warning() -> None:
    rows = [r for x in (
        "robot:robot.module=(base)", "robot:interlock.rule=(old_style)",
        "robot:interlock.rule=(digging_creep,info)", "robot:interlock.rule=(bumper,error)",
        "robot:interlock.message=(bumper,Back away)") for r in parse_response_line(x.encode())]
    cat = build_catalog(rows, {})
    assert cat.interlocks == {"old_style": InterlockInfo("old_style", "warning"),
                              "digging_creep": InterlockInfo("digging_creep", "info"),
                              "bumper": InterlockInfo("bumper", "error", "Back away")}


def test_latched_faults_come_from_describe_s_reset_functions_not_a_property_name() -> None:
    rows = [r for x in (
        "ble:lift.function=(vel,int -100..100)", "ble:lift.function=(reset)",
        "ble:lift.property=(vel,int)", "ble:lift.property=(pos,float)",
        "ble:lift.property=(overheated,int)", "ble:chain.function=(vel,int -100..100)",
        "ble:chain.property=(vel,int)", "ble:chain.property=(stalled,int)")
            for r in parse_response_line(x.encode())]
    cat = build_catalog(parse_response_line(b"robot:robot.module=(ble)"), {"ble": rows})
    assert latch_flags(cat) == ("ble:lift.overheated",)
    alerts = ids(Inputs(values={"ble:lift.overheated": "1", "ble:lift.vel": "1",
                                "ble:chain.stalled": "1"}, latches=latch_flags(cat)))
    assert alerts == {"latched:ble:lift": "error"}


def test_a_battery_s_charge_in_percent_is_read_as_the_robot_gives_it() -> None:
    i = Inputs(values={"base:battery.charge": "99.3", "base:battery.volt": "12.57"},
               batteries=("base:battery.charge",))
    assert ids(i) == {}  # a fresh 3S pack, whatever --battery says
    i.values["base:battery.charge"] = "12.0"
    alert = raised(i)[0]
    assert alert.id == "battery:base:battery.charge" and "12 %" in alert.text
