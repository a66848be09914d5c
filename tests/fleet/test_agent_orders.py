"""A VDA 5050 order driven node to node, end to end: a real Mosquitto, the real
`ramp-fleet-agent` process, and a simulated MARTE with the autonomy on the virtual clock in
this process (tests/fleet/virtual_robot.py: the backend and the autonomy's command endpoint on
loopback). An order of three nodes, a dig at the second and a dump at the collector: the
nodes and edges left shrink, `lastNodeId` advances, the actions finish, the regolith reaches
the collector; a node without a position is refused with an orderError; every message
validates against the VDA 5050 2.1.0 schemas."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from ramp.fleet import vda5050 as v
from ramp.fleet.broker import LocalBroker
from tests.fleet.schemas import validate
from tests.fleet.virtual_robot import ASK_EVERY_S, VirtualRobot
from tests.fleet_fixtures import Collector, start_agent
from tests.harness import stop_process

SERIAL = "marte-orders"
H = v.Headers("RAMP", SERIAL)


@pytest.fixture
def robot() -> Iterator[VirtualRobot]:
    r = VirtualRobot(seed=1)
    yield r
    r.close()


def action(state: dict[str, Any], action_id: str) -> dict[str, Any]:
    return next((a for a in state["actionStates"] if a["actionId"] == action_id), {})


def test_an_order_of_three_nodes_digs_and_dumps(robot: VirtualRobot, mosquitto: LocalBroker,
                                                tmp_path: Path) -> None:
    col = Collector(mosquitto.host, mosquitto.port, [f"uagv/v2/RAMP/{SERIAL}/#"])
    agent = start_agent("ramp.yaml", "{}:{}".format(*robot.mcp), mosquitto.address, SERIAL,
                        str(tmp_path), "--autonomy", robot.commands)

    def states() -> list[dict[str, Any]]:
        return col.json("/state")

    def seen(pred: Callable[[dict[str, Any]], bool]) -> Callable[[], bool]:
        return lambda: any(pred(m) for m in states())

    def publish(name: str, msg: dict[str, Any]) -> None:
        validate(name, msg)
        col.client.publish(v.topic("RAMP", SERIAL, name), json.dumps(msg), qos=1)

    try:
        robot.run_until(lambda: any(
            {"dig", "dump"} <= {a["actionType"] for a in m["protocolFeatures"]["agvActions"]}
            for m in col.json("/factsheet")), wall_s=30, every_s=ASK_EVERY_S)
        robot.run_until(seen(lambda m: any(i["infoType"] == "missionState"
                                           for i in m["information"])),
                        wall_s=30, every_s=ASK_EVERY_S)
        # A node without a position: refused, and the state says why.
        publish("order", v.order(H, "bad", [
            v.node("here", 0, 0.75, 1.4),
            {"nodeId": "nowhere", "sequenceId": 2, "released": True, "actions": []}]))
        robot.run_until(seen(lambda m: any(
            e["errorType"] == "orderError" and "nowhere" in e["errorDescription"]
            and "no nodePosition" in e["errorDescription"] for e in m["errors"])),
            wall_s=20, every_s=ASK_EVERY_S)
        # Three released nodes and one on the horizon.
        nodes = [
            v.node("n1", 0, 0.75, 1.4, theta=0.0),
            v.node("n2", 2, 3.9, 1.0, theta=0.0,
                   actions=[v.action("dig", "dig-1", parameters={"seconds": 8})]),
            v.node("n3", 4, 0.6, 1.94, actions=[v.action("dump", "dump-1")]),
            v.node("n4", 6, 2.0, 1.0, released=False),
        ]
        order = v.order(H, "o1", nodes)
        order["edges"][-1]["released"] = False
        publish("order", order)
        robot.run_until(seen(lambda m: m["orderId"] == "o1" and action(m, "dump-1").get(
            "actionStatus") in ("FINISHED", "FAILED")),
            wall_s=120, sim_s=900, every_s=ASK_EVERY_S)
        mine = [m for m in states() if m["orderId"] == "o1"]
        last = mine[-1]
        assert action(last, "dump-1")["actionStatus"] == "FINISHED", last["actionStates"]
        assert action(last, "dig-1")["actionStatus"] == "FINISHED"
        assert "kg in the bin" in action(last, "dig-1")["resultDescription"]
        assert last["lastNodeId"] == "n3" and last["lastNodeSequenceId"] == 4
        assert [n["nodeId"] for n in last["nodeStates"]] == ["n4"]  # the horizon waits
        # Node by node: lastNodeId advances, the nodes and edges left shrink.
        order_seen: list[str] = []
        for m in mine:
            if not order_seen or order_seen[-1] != m["lastNodeId"]:
                order_seen.append(m["lastNodeId"])
        assert order_seen == ["", "n1", "n2", "n3"], order_seen
        left = [(len(m["nodeStates"]), len(m["edgeStates"])) for m in mine]
        assert left == sorted(left, reverse=True) and left[0] == (4, 3) and left[-1] == (1, 1)
        at_n2 = next(m for m in mine if m["lastNodeId"] == "n2")
        assert [e["edgeId"] for e in at_n2["edgeStates"]] == ["n2-n3", "n3-n4"]
        dig_states = [action(m, "dig-1")["actionStatus"] for m in mine]
        assert dig_states.index("WAITING") < dig_states.index("RUNNING") \
            < dig_states.index("FINISHED")
        assert any(m["driving"] and m["operatingMode"] == "SEMIAUTOMATIC" for m in mine)
        assert robot.world.delivered_kg > 1.0  # the referee's count, at the collector
        assert robot.world.truth()["collisions"] == 0
        for m in states():
            validate("state", m)
        for m in col.json("/visualization")[-20:]:
            validate("visualization", m)
    finally:
        stop_process(agent)
        col.close()
