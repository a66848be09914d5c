"""The VDA 5050 2.1.0 builders against the official schemas, and the parsers' refusals."""

from __future__ import annotations

import json

import jsonschema
import pytest

from ramp.fleet import vda5050 as v
from tests.fleet.schemas import SCHEMAS, validate


def test_the_official_schemas_and_their_licence_are_kept() -> None:
    assert "Verband der Automobilindustrie" in (SCHEMAS / "LICENSE.txt").read_text()
    for kind in ("connection", "state", "visualization", "factsheet", "order",
                 "instantActions"):
        schema = json.loads((SCHEMAS / f"{kind}.schema").read_text())
        assert schema["$schema"].endswith("2020-12/schema")


def test_every_built_message_validates() -> None:
    h = v.Headers("RAMP", "marte-1")
    for state in (v.ONLINE, v.OFFLINE, v.CONNECTIONBROKEN):
        validate("connection", v.connection(h, state))
    pos = v.position(1.5, 2.0, 4.0, score=0.93)
    assert -3.15 < pos["theta"] < 3.15
    validate("visualization", v.visualization(h, pos, {"vx": 0.1, "vy": 0.0, "omega": 0.0}))
    validate("visualization", v.visualization(h))
    n = [v.node("a", 0, 1.0, 1.0), v.node("b", 2, 6.0, 1.9, theta=0.0,
                                           actions=[v.action("dig", "d1")])]
    o = v.order(v.Headers("RAMP", "marte-1"), "o1", n)
    validate("order", o)
    fields = v.StateFields(
        order_id="o1", last_node_id="a", node_states=[v.node_state(x) for x in n],
        edge_states=[v.edge_state(e) for e in o["edges"]], driving=True, paused=False,
        operating_mode=v.SEMIAUTOMATIC,
        action_states=[v.action_state("x", "stopPause", v.FINISHED, "stopped")],
        battery_state=v.battery(87.5, voltage=25.1),
        errors=[v.error("moduleFault", v.FATAL, "ble in fault", {"module": "ble"})],
        information=[v.info("missionState", "excavate")], agv_position=pos)
    validate("state", v.state(h, fields))
    validate("state", v.state(h, v.StateFields()))
    sheet = v.factsheet(h, v.FactsheetFields(
        "MARTE", "RMC mining robot", 0.5, 1.2, 0.75, 0.8,
        [v.agv_action("stopPause", "stop", ["INSTANT"]),
         v.agv_action("rmcMission", "mission", ["NODE"],
                      [("seed", "INTEGER", "seed", True)])],
        versions={"ramp": "0.1.0"}, localization=True))
    validate("factsheet", sheet)
    validate("instantActions", v.instant_actions(
        h, [v.action("stopPause", "s1"), v.action("rmcMission", "m", parameters={"seed": 3})]))


def test_header_ids_count_per_topic() -> None:
    h = v.Headers("RAMP", "s")
    assert [v.state(h, v.StateFields())["headerId"] for _ in range(3)] == [0, 1, 2]
    assert v.connection(h, v.ONLINE)["headerId"] == 0
    assert v.timestamp(0.0) == "1970-01-01T00:00:00.000Z"


def test_a_broken_message_fails_the_schema() -> None:
    msg = v.state(v.Headers("RAMP", "s"), v.StateFields())
    del msg["batteryState"]
    with pytest.raises(jsonschema.ValidationError):
        validate("state", msg)


def test_topics() -> None:
    assert v.topic("RAMP", "marte-1", "state") == "uagv/v2/RAMP/marte-1/state"
    assert v.split_topic("uagv/v2/RAMP/marte-1/order") == ("RAMP", "marte-1", "order")
    assert v.split_topic("uagv/v1/RAMP/marte-1/order") is None


def test_parsers_refuse_in_words() -> None:
    with pytest.raises(v.MessageError, match="not JSON"):
        v.decode(b"{")
    with pytest.raises(v.MessageError, match="actionId is missing"):
        v.parse_instant_actions({"actions": [{"actionType": "stopPause"}]})
    acts = v.parse_instant_actions(v.instant_actions(
        v.Headers("M", "s"), [v.action("rmcMission", "a", parameters={"seed": 4})]))
    assert acts[0].parameters == {"seed": 4}
    o = v.parse_order(v.order(v.Headers("M", "s"), "o", [v.node("a", 0, 1, 2)]))
    assert (o.nodes[0].x, o.nodes[0].y) == (1.0, 2.0)
    with pytest.raises(v.MessageError, match=r"nodes\[0\].nodePosition: x"):
        v.parse_order({"orderId": "o", "orderUpdateId": 0, "edges": [],
                       "nodes": [{"nodeId": "a", "sequenceId": 0, "released": True,
                                  "nodePosition": {"x": "1", "y": 0, "mapId": "arena"}}]})
    with pytest.raises(v.MessageError, match="nodes is empty"):
        v.parse_order({"orderId": "o", "orderUpdateId": 0, "nodes": [], "edges": []})
