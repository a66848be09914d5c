"""The console's alerts (SPEC 7.1): what raises each, its severity and advice, the order."""

from __future__ import annotations

from ramp.teleop.alerts import AlertBook, Inputs, raised


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
               batteries=("base:battery.volt",))
    alerts = {a.id: a for a in raised(i)}
    assert {k: a.severity for k, a in alerts.items()} == {
        "module:ble": "error", "latched:ble:lift": "error", "interlock": "warning",
        "watchdog": "warning", "battery:base:battery.volt": "warning"}
    latched = alerts["latched:ble:lift"]
    assert latched.reset == "ble:lift" and "ble:lift.reset=()" in latched.text
    assert "ladder_down_slow" in alerts["interlock"].title
    assert "10 %" in alerts["battery:base:battery.volt"].text
    assert latched.view(1.0)["takeover"] and not alerts["watchdog"].view(1.0)["takeover"]


def test_a_lost_robot_link_is_an_error() -> None:
    assert ids(Inputs(robot_reachable=False, robot_detail="refused")) == {"robot-link": "error"}


def test_the_autonomy_lost_waiting_or_unsure_raises_its_alerts() -> None:
    assert ids(Inputs(autonomy=view(state="relocalize", lost=True))) == {
        "localization": "error"}
    assert ids(Inputs(autonomy=view(state="stop", lost=True))) == {"localization": "error"}
    # Re-localizing after a hand-back is not being lost.
    assert ids(Inputs(autonomy=view(state="relevel", lost=False))) == {"localization": "info"}
    waiting = raised(Inputs(autonomy=view(state="waiting_for_operator",
                                          reason="still lost after 3 relocalization tries")))
    assert [(a.id, a.severity) for a in waiting] == [("mission-waiting", "error")]
    assert "still lost after 3" in waiting[0].text and "Hand back" in waiting[0].text
    assert ids(Inputs(autonomy=view(numbers={"pose_confidence": 0.3}))) == {
        "confidence": "warning"}
    # Before the first fix a zero confidence is no alarm.
    assert ids(Inputs(autonomy=view(state="initial_localization",
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
    book = AlertBook()
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
