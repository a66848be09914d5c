"""The agent's order runner (ramp/fleet/orders.py) on the real `Agent`, with the autonomy's
command endpoint played by a stand-in that answers as ramp/autonomy/command.py does: node by
node, `nodeStates`/`edgeStates` shrink and `lastNodeId` advances, node actions go WAITING ->
RUNNING -> FINISHED/FAILED, the base is driven and the horizon waits, updates stitch at the
last base node, bad orders are refused with an orderError; every `state` validates against
the VDA 5050 2.1.0 schema. (The same against a simulated robot: test_agent_orders.py.)"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from ramp.autonomy import arena
from ramp.fleet import orders as orders_mod
from ramp.fleet import vda5050 as v
from ramp.fleet.agent import Agent
from ramp.fleet.orders import Orders
from ramp.fleet.pause import PauseStore
from tests.fleet.schemas import validate

H = v.Headers("RAMP", "marte-1")


class FakeLink:
    address = "127.0.0.1:1"
    fault = ""
    connected = True
    on_connect: Any = None
    on_lost_cb: Any = None

    def send(self, *_: Any) -> bool:
        return True


class FakeMqtt:
    headers = v.Headers("RAMP", "marte-1")

    def __init__(self) -> None:
        self.sent: list[tuple[str, dict[str, Any]]] = []

    def publish(self, name: str, message: dict[str, Any], *, retain: bool = False,
                qos: int = 0) -> bool:
        self.sent.append((name, message))
        return True


class FakeAutonomy:
    """Answers like the command endpoint; the test sets the task's progress."""

    address = "127.0.0.1:2"
    fault = ""
    connected = True

    def __init__(self) -> None:
        self.commands: list[tuple[str, dict[str, Any]]] = []
        self.status: dict[str, Any] = {"state": "paused", "held": "waiting", "over": False,
                                       "outcome": "running", "pose": {"x": 0.7, "y": 1.0,
                                                                      "yaw": 0.0},
                                       "confidence": 0.9, "bin_kg": 0.0, "delivered_kg": 0.0,
                                       "task": None}
        self.refuse = ""

    def command(self, cmd: str, on_reply: Callable[[dict[str, Any]], None] | None = None,
                **args: Any) -> bool:
        self.commands.append((cmd, args))
        if cmd in ("goto", "dig", "dump") and not self.refuse:
            self.task(args["id"], cmd, "running", "acquire_control")
        if on_reply is not None:
            on_reply({"ok": not self.refuse, "error": self.refuse} if self.refuse
                     else {"ok": True})
        return True

    def task(self, task_id: str, kind: str, state: str, step: str, reason: str = "") -> None:
        self.status["task"] = {"kind": kind, "id": task_id, "state": state, "step": step,
                               "reason": reason}

    def tick(self, now: float, dt: float) -> None:
        pass


class Rig:
    def __init__(self, tmp: Path) -> None:
        self.t = 0.0
        self.mqtt = FakeMqtt()
        self.auto = FakeAutonomy()
        self.agent = Agent(FakeLink(), self.mqtt, PauseStore(tmp, "marte-1"),  # type: ignore[arg-type]
                           now=lambda: self.t, autonomy=self.auto)
        self.agent.orders = self.orders = Orders(self.agent, self.auto)
        self.agent.status = SimpleNamespace(owner="none")  # type: ignore[assignment]

    def send(self, msg: dict[str, Any]) -> None:
        validate("order", msg)
        self.agent.handle("uagv/v2/RAMP/marte-1/order", json.dumps(msg).encode())

    def step(self) -> dict[str, Any]:
        """A poll answered, a tick of the runner; the state it would publish."""
        self.t += 0.05
        self.agent.status_seq += 1
        self.orders.tick(self.t)
        msg = v.state(H, self.agent.state_fields())
        validate("state", msg)
        return msg

    def last(self, cmd: str) -> dict[str, Any]:
        return next(a for c, a in reversed(self.auto.commands) if c == cmd)


def action(state: dict[str, Any], action_id: str) -> dict[str, Any]:
    return next(a for a in state["actionStates"] if a["actionId"] == action_id)


def nodes(state: dict[str, Any]) -> list[str]:
    return [n["nodeId"] for n in state["nodeStates"]]


def edges(state: dict[str, Any]) -> list[str]:
    return [e["edgeId"] for e in state["edgeStates"]]


def three_nodes(horizon: bool = True) -> list[dict[str, Any]]:
    out = [
        v.node("n1", 0, 0.9, 1.0, theta=0.0),
        v.node("n2", 2, 3.9, 1.0, theta=0.0, actions=[
            v.action("dig", "dig-1", parameters={"seconds": 8})]),
        v.node("n3", 4, 0.6, 1.94, actions=[v.action("dump", "dump-1")]),
    ]
    if horizon:
        out.append(v.node("n4", 6, 2.0, 1.0, released=False))
    return out


def test_an_order_is_driven_node_by_node_with_dig_and_dump(tmp_path: Path) -> None:
    rig = Rig(tmp_path)
    o = v.order(H, "o1", three_nodes())
    o["edges"][-1]["released"] = False  # the edge into the horizon
    rig.send(o)
    st = rig.step()
    assert st["orderId"] == "o1" and nodes(st) == ["n1", "n2", "n3", "n4"]
    assert len(st["edgeStates"]) == 3 and st["lastNodeId"] == ""
    assert action(st, "dig-1")["actionStatus"] == "WAITING"
    assert action(st, "dump-1")["actionStatus"] == "WAITING"
    st = rig.step()
    goto = rig.last("goto")
    assert (goto["x"], goto["y"], goto["theta"]) == (0.9, 1.0, 0.0)
    rig.auto.task(goto["id"], "goto", "done", "goto", "reached x 0.90 y 1.00")
    st = rig.step()
    assert st["lastNodeId"] == "n1" and st["lastNodeSequenceId"] == 0
    assert rig.orders.running  # between two nodes' tasks: still the order's (SEMIAUTOMATIC)
    assert nodes(st) == ["n2", "n3", "n4"]
    assert edges(st) == ["n1-n2", "n2-n3", "n3-n4"]  # the way to n2 is still ahead
    st = rig.step()
    goto = rig.last("goto")
    assert (goto["x"], goto["y"]) == (3.9, 1.0)
    rig.auto.task(goto["id"], "goto", "running", "scan_for_obstacles", "arrived")
    st = rig.step()
    assert st["lastNodeId"] == "n1" and action(st, "dig-1")["actionStatus"] == "WAITING"
    rig.auto.task(goto["id"], "goto", "done", "goto", "reached")
    st = rig.step()
    assert st["lastNodeId"] == "n2" and nodes(st) == ["n3", "n4"]
    assert edges(st) == ["n2-n3", "n3-n4"]
    st = rig.step()
    assert rig.last("dig") == {"id": "dig-1", "seconds": 8}
    assert action(st, "dig-1")["actionStatus"] == "RUNNING"
    rig.auto.task("dig-1", "dig", "done", "dig", "2.3 kg in the bin after 8 s of digging")
    st = rig.step()
    assert action(st, "dig-1") == {"actionId": "dig-1", "actionType": "dig",
                                   "actionStatus": "FINISHED",
                                   "resultDescription": "2.3 kg in the bin after 8 s of "
                                                        "digging"}
    st = rig.step()
    assert "dump" in [c for c, _ in rig.auto.commands]
    assert not any(a.get("x") == 0.6 for c, a in rig.auto.commands if c == "goto"), \
        "the collector node is reached by the dump itself"
    rig.auto.task("dump-1", "dump", "running", "cross_home", "to the collector")
    st = rig.step()
    assert st["lastNodeId"] == "n2" and action(st, "dump-1")["actionStatus"] == "RUNNING"
    rig.auto.task("dump-1", "dump", "running", "deposit", "both docking buttons pressed")
    st = rig.step()
    assert st["lastNodeId"] == "n3" and st["lastNodeSequenceId"] == 4
    rig.auto.task("dump-1", "dump", "done", "decouple", "clear of the collector")
    st = rig.step()
    assert action(st, "dump-1")["actionStatus"] == "FINISHED"
    assert nodes(st) == ["n4"] and st["nodeStates"][0]["released"] is False
    assert [e["released"] for e in st["edgeStates"]] == [False]
    assert not rig.orders.active  # the base is done: a new order may come
    # An update stitched at the last base node extends the order.
    rig.send(v.order(H, "o1", [v.node("n3", 4, 0.6, 1.94), v.node("n5", 6, 1.0, 1.5)],
                     update_id=1))
    st = rig.step()
    st = rig.step()
    assert st["orderUpdateId"] == 1 and nodes(st) == ["n5"]
    goto = rig.last("goto")
    assert (goto["x"], goto["y"]) == (1.0, 1.5)
    assert [c for c, _ in rig.auto.commands].count("dump") == 1  # not run twice
    # An update that does not begin at the last base node is refused.
    rig.send(v.order(H, "o1", [v.node("n1", 0, 0.9, 1.0), v.node("n6", 2, 1.0, 1.5)],
                     update_id=2))
    st = rig.step()
    err = next(e for e in st["errors"] if e["errorType"] == "orderUpdateError")
    assert "n5" in err["errorDescription"]  # the base now ends there
    rig.auto.task(goto["id"], "goto", "done", "goto", "reached")
    st = rig.step()
    assert st["lastNodeId"] == "n5" and nodes(st) == [] and st["edgeStates"] == []


@pytest.mark.parametrize(("node", "words"), [
    (v.node("far", 2, 9.0, 1.0), "outside the arena"),
    ({"nodeId": "blind", "sequenceId": 2, "released": True, "actions": []},
     "has no nodePosition"),
    (v.node("bin", 2, 3.0, 1.0, actions=[v.action("dump", "d")]), "at the collector"),
    (v.node("lift", 2, 3.0, 1.0, actions=[v.action("pick", "p")]), "unsupported action"),
    ({"nodeId": "else", "sequenceId": 2, "released": True, "actions": [],
      "nodePosition": {"x": 1.0, "y": 1.0, "mapId": "warehouse"}}, "map 'warehouse'"),
])
def test_a_bad_node_is_an_order_error(tmp_path: Path, node: dict[str, Any],
                                      words: str) -> None:
    rig = Rig(tmp_path)
    rig.send(v.order(H, "bad", [v.node("a", 0, 0.9, 1.0), node]))
    st = rig.step()
    err = next(e for e in st["errors"] if e["errorType"] == "orderError")
    assert words in err["errorDescription"], err
    assert st["orderId"] == "" and rig.auto.commands == []


def test_a_node_out_of_reach_fails_the_order_and_cancel_stops_it(tmp_path: Path) -> None:
    rig = Rig(tmp_path)
    rig.send(v.order(H, "o1", three_nodes(horizon=False)))
    rig.step()
    rig.step()
    goto = rig.last("goto")
    rig.auto.task(goto["id"], "goto", "failed", "goto", "goto: no way to x 0.90 y 1.00")
    st = rig.step()
    err = next(e for e in st["errors"] if e["errorType"] == "noRouteError")
    assert "no way" in err["errorDescription"]
    assert action(st, "dig-1")["actionStatus"] == "FAILED"
    assert "not run" in action(st, "dig-1")["resultDescription"]
    assert st["nodeStates"] == [] and not rig.orders.active
    # A new order; cancelOrder while it drives: the task is cancelled, nothing is left.
    rig.send(v.order(H, "o2", three_nodes(horizon=False)))
    rig.step()
    rig.step()
    rig.agent.instant(v.parse_action(v.action("cancelOrder", "c1")))
    assert rig.auto.commands[-1][0] == "cancel"
    st = rig.step()
    assert action(st, "c1")["actionStatus"] == "FINISHED"
    assert action(st, "dig-1")["resultDescription"] == "cancelled by cancelOrder"
    assert st["nodeStates"] == [] and st["edgeStates"] == []


def test_an_order_waits_for_an_operator(tmp_path: Path) -> None:
    rig = Rig(tmp_path)
    rig.agent.status = SimpleNamespace(owner="ana")  # type: ignore[assignment]
    rig.send(v.order(H, "o1", three_nodes(horizon=False)))
    for _ in range(3):
        st = rig.step()
    assert rig.auto.commands == []
    assert any("ana holds control" in i["infoDescription"] for i in st["information"])
    rig.agent.status = SimpleNamespace(owner="none")  # type: ignore[assignment]
    rig.step()
    assert rig.auto.commands[-1][0] == "goto"


def test_the_factsheet_names_dig_and_dump_at_nodes(tmp_path: Path) -> None:
    rig = Rig(tmp_path)
    sheet = rig.agent.factsheet()
    validate("factsheet", sheet)
    acts = {a["actionType"]: a for a in sheet["protocolFeatures"]["agvActions"]}
    assert acts["dig"]["actionScopes"] == ["NODE"] and acts["dump"]["actionScopes"] == ["NODE"]
    assert acts["dig"]["actionParameters"][0]["key"] == "seconds"


def test_the_fleet_knows_the_arena_as_the_autonomy_does() -> None:
    assert orders_mod.ARENA_LENGTH_M == arena.ARENA_LENGTH_M
    assert orders_mod.ARENA_WIDTH_M == arena.ARENA_WIDTH_M
    assert orders_mod.COLLECTOR_XY == (arena.ROBOT_LENGTH_M / 2, arena.COLLECTOR_Y_M)


def test_the_docs_example_order_is_valid_and_runs_here() -> None:
    doc = (Path(__file__).resolve().parents[2] / "docs" / "operating" / "fleet.md").read_text()
    block = doc.split("An example (a dig", 1)[1].split("```json", 1)[1].split("```", 1)[0]
    msg = json.loads(block)
    validate("order", msg)
    order = v.parse_order(msg)
    assert orders_mod.check(order) == ""
    assert [w.kind for w in orders_mod.plan_work(order, 0, "o1")] == [
        "goto", "goto", "dig", "dump"]
