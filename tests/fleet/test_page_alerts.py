"""The fleet page's alerts follow the console's model (SPEC 7.1): severities, kept while their
cause holds with their first-raised time, ordered by severity then recency, each saying what to
do; fed only with VDA 5050 messages written by hand."""

from __future__ import annotations

import json
from typing import Any

from ramp.fleet import vda5050 as v
from ramp.fleet.page.alerts import STOP_LATE_S, Alert, Board
from ramp.fleet.page.supervisor import FleetSupervisor


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def supervisor() -> tuple[FleetSupervisor, FakeClock, list[dict[str, Any]]]:
    clock = FakeClock()
    sup = FleetSupervisor("127.0.0.1", 1, clock=clock)
    sent: list[dict[str, Any]] = []
    sup.client.publish = lambda topic, payload, qos=0: sent.append(  # type: ignore[method-assign]
        json.loads(payload))
    sup.connected.set()
    return sup, clock, sent


def feed(sup: FleetSupervisor, serial: str, name: str, msg: dict[str, Any]) -> None:
    sup.receive(f"uagv/v2/ACME/{serial}/{name}", json.dumps(msg).encode())


def state(serial: str, *, driving: bool = False, charge: float = 80.0,
          errors: list[dict[str, Any]] | None = None,
          actions: list[dict[str, Any]] | None = None,
          information: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    f = v.StateFields()
    f.driving = driving
    f.battery_state = v.battery(charge, voltage=20.0)
    f.errors = errors or []
    f.action_states = actions or []
    f.information = information or []
    return v.state(v.Headers("ACME", serial), f)


def ids(sup: FleetSupervisor) -> list[str]:
    return [a["id"] for a in sup.snapshot()["alerts"]]


def shown(board: Board, alerts: list[Alert], now: float) -> list[dict[str, Any]]:
    """The page's list after `alerts` were raised at `now`."""
    board.update(alerts, now)
    return board.view(now)


def test_alerts_are_ordered_by_severity_then_recency_and_keep_their_first_time() -> None:
    board = Board()
    warn = Alert("a", "warning", "A", "a")
    err = Alert("b", "error", "B", "b")
    info = Alert("c", "info", "C", "c")
    assert [a["id"] for a in shown(board, [info, warn], 10.0)] == ["a", "c"]
    later = Alert("d", "warning", "D", "d")
    out = shown(board, [info, warn, err, later], 15.0)
    assert [a["id"] for a in out] == ["b", "d", "a", "c"]  # the newer warning first
    assert [a["for_s"] for a in out] == [0.0, 0.0, 5.0, 5.0]
    out = shown(board, [warn], 20.0)  # the others cleared: forgotten
    assert [(a["id"], a["for_s"]) for a in out] == [("a", 10.0)]
    assert shown(board, [warn, err], 21.0)[0] == {
        "id": "b", "severity": "error", "title": "B", "text": "b", "serial": "", "for_s": 0.0}


def test_a_robots_errors_are_alerts_with_their_level_and_hint() -> None:
    sup, _clock, _sent = supervisor()
    feed(sup, "digger-7", "state", state("digger-7", errors=[
        v.error("interlockActive", v.WARNING, "interlock tilt is active",
                {"interlock": "tilt"}),
        v.error("latchedFault", v.FATAL, "ble:lift.stalled is latched",
                {"device": "ble:lift"}, hint="ble:lift.reset=() once the cause is cleared")]))
    alerts = sup.snapshot()["alerts"]
    assert [(a["severity"], a["title"]) for a in alerts] == [
        ("error", "digger-7: latchedFault"), ("warning", "digger-7: interlockActive")]
    assert "ble:lift.reset=()" in alerts[0]["text"] and alerts[0]["serial"] == "digger-7"
    feed(sup, "digger-7", "state", state("digger-7"))  # cleared on the robot: gone here
    assert sup.snapshot()["alerts"] == []


def test_a_stop_not_confirmed_in_time_is_an_error_until_the_robot_confirms_it() -> None:
    sup, clock, sent = supervisor()
    feed(sup, "scout-1", "state", state("scout-1", driving=True))
    sup.stop_all()
    action_id = sent[-1]["actions"][0]["actionId"]
    clock.t += STOP_LATE_S - 0.1
    assert ids(sup) == []
    clock.t += 0.2
    assert ids(sup) == ["scout-1:stop-late"]
    alert = sup.snapshot()["alerts"][0]
    assert alert["severity"] == "error" and "console" in alert["text"]
    feed(sup, "scout-1", "state", state("scout-1", driving=False, actions=[
        v.action_state(action_id, "stopPause", "FINISHED")]))
    assert ids(sup) == []


def test_connection_silence_battery_and_the_broker() -> None:
    sup, clock, _sent = supervisor()
    feed(sup, "a", "connection", v.connection(v.Headers("ACME", "a"), v.ONLINE))
    feed(sup, "a", "state", state("a", charge=15.0))
    feed(sup, "b", "state", state("b", charge=5.0, information=[
        v.info("batteryChargeUnknown", "no battery model")]))  # an unknown charge is no alarm
    assert ids(sup) == ["a:battery"]
    clock.t += 40
    feed(sup, "b", "state", state("b", charge=90.0))
    assert ids(sup) == ["a:silent", "a:battery"]  # the newest first among warnings
    feed(sup, "a", "connection", v.connection(v.Headers("ACME", "a"), v.CONNECTIONBROKEN))
    got = sup.snapshot()["alerts"]
    assert (got[0]["id"], got[0]["severity"]) == ("a:connection", "error")
    assert "a:silent" not in ids(sup)  # broken says more than silent
    clock.t += 1
    sup.connected.clear()
    assert ids(sup)[0:2] == ["broker", "a:connection"]
