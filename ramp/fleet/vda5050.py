"""VDA 5050 2.1.0 messages: builders for what a robot and a supervisor publish, and parsers
for what they receive. Plain dicts in, JSON-ready dicts out: the official JSON schemas
(tests/data/vda5050/, VDA's MIT licence beside them) are the contract the tests check every
built message against; the parsers check what the agent relies on and say in words what is
wrong, so a bad message from a master is answered, never crashes the agent.

Topics: `uagv/v2/{manufacturer}/{serialNumber}/{connection|state|visualization|factsheet|
order|instantActions}` (VDA 5050 2.1.0, section 6.4: interface name, major version).
"""

from __future__ import annotations

import datetime as _dt
import itertools
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

VERSION = "2.1.0"
INTERFACE = "uagv"
MAJOR = "v2"
#: The map every arena-frame position is on (SPEC 6.1's frame).
MAP_ID = "arena"

ROBOT_TOPICS = ("connection", "state", "visualization", "factsheet")
MASTER_TOPICS = ("order", "instantActions")

ONLINE, OFFLINE, CONNECTIONBROKEN = "ONLINE", "OFFLINE", "CONNECTIONBROKEN"
WAITING, INITIALIZING, RUNNING, FINISHED, FAILED = (
    "WAITING", "INITIALIZING", "RUNNING", "FINISHED", "FAILED")
AUTOMATIC, SEMIAUTOMATIC, MANUAL, SERVICE = "AUTOMATIC", "SEMIAUTOMATIC", "MANUAL", "SERVICE"
WARNING, FATAL = "WARNING", "FATAL"
INFO = "INFO"

#: The instant actions every RAMP robot answers (SPEC 14).
INSTANT_ACTIONS = ("stopPause", "startPause", "cancelOrder", "stateRequest", "factsheetRequest")
#: The order actions of a robot with the autonomy.
ORDER_ACTIONS = ("rmcMission", "dig", "dump")


class MessageError(ValueError):
    """A received message that cannot be used; str() says what and where."""


def topic(manufacturer: str, serial: str, name: str) -> str:
    return f"{INTERFACE}/{MAJOR}/{manufacturer}/{serial}/{name}"


def split_topic(text: str) -> tuple[str, str, str] | None:
    """`uagv/v2/M/S/NAME` -> (M, S, NAME); None for any other topic."""
    parts = text.split("/")
    if len(parts) != 5 or parts[0] != INTERFACE or parts[1] != MAJOR:
        return None
    return parts[2], parts[3], parts[4]


def timestamp(now: float | None = None) -> str:
    """ISO 8601 in UTC with milliseconds, as the standard's examples write it."""
    t = _dt.datetime.now(_dt.UTC) if now is None else _dt.datetime.fromtimestamp(now, _dt.UTC)
    return t.strftime("%Y-%m-%dT%H:%M:%S.") + f"{t.microsecond // 1000:03d}Z"


class Headers:
    """The header fields of one sender: `headerId` counts per topic (VDA 5050 6.5)."""

    def __init__(self, manufacturer: str, serial: str) -> None:
        self.manufacturer = manufacturer
        self.serial = serial
        self._ids: dict[str, itertools.count[int]] = {}

    def next(self, name: str, now: float | None = None) -> dict[str, Any]:
        counter = self._ids.setdefault(name, itertools.count(0))
        return {"headerId": next(counter), "timestamp": timestamp(now), "version": VERSION,
                "manufacturer": self.manufacturer, "serialNumber": self.serial}

    def topic(self, name: str) -> str:
        return topic(self.manufacturer, self.serial, name)


# -- robot -> master ------------------------------------------------------------------------------
def connection(headers: Headers, state: str, now: float | None = None) -> dict[str, Any]:
    return {**headers.next("connection", now), "connectionState": state}


def position(x: float, y: float, theta: float, *, initialized: bool = True,
             score: float | None = None) -> dict[str, Any]:
    """An `agvPosition` on the arena map; theta in radians, wrapped to -pi..pi."""
    pos: dict[str, Any] = {"x": round(x, 4), "y": round(y, 4),
                           "theta": round(math.remainder(theta, 2 * math.pi), 4),
                           "mapId": MAP_ID, "positionInitialized": initialized}
    if score is not None:
        pos["localizationScore"] = round(min(1.0, max(0.0, score)), 3)
    return pos


def visualization(headers: Headers, agv_position: Mapping[str, Any] | None = None,
                  velocity: Mapping[str, float] | None = None,
                  now: float | None = None) -> dict[str, Any]:
    msg = headers.next("visualization", now)
    if agv_position is not None:
        msg["agvPosition"] = dict(agv_position)
    if velocity is not None:
        msg["velocity"] = dict(velocity)
    return msg


def action_state(action_id: str, action_type: str, status: str,
                 result: str = "", description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {"actionId": action_id, "actionType": action_type,
                           "actionStatus": status}
    if description:
        out["actionDescription"] = description
    if result:
        out["resultDescription"] = result
    return out


def error(error_type: str, level: str, description: str,
          references: Mapping[str, str] | None = None, hint: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {"errorType": error_type, "errorLevel": level,
                           "errorDescription": description}
    if references:
        out["errorReferences"] = [{"referenceKey": k, "referenceValue": str(v)}
                                  for k, v in references.items()]
    if hint:
        out["errorHint"] = hint
    return out


def info(info_type: str, description: str,
         references: Mapping[str, str] | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {"infoType": info_type, "infoLevel": INFO,
                           "infoDescription": description}
    if references:
        out["infoReferences"] = [{"referenceKey": k, "referenceValue": str(v)}
                                 for k, v in references.items()]
    return out


def battery(charge: float, *, voltage: float | None = None,
            charging: bool = False) -> dict[str, Any]:
    out: dict[str, Any] = {"batteryCharge": round(charge, 1), "charging": charging}
    if voltage is not None:
        out["batteryVoltage"] = round(voltage, 3)
    return out


@dataclass
class StateFields:
    """What a `state` message says beyond its header; `state()` turns it into the message."""

    order_id: str = ""
    order_update_id: int = 0
    last_node_id: str = ""
    last_node_sequence_id: int = 0
    node_states: list[dict[str, Any]] = field(default_factory=list)
    edge_states: list[dict[str, Any]] = field(default_factory=list)
    driving: bool = False
    paused: bool = False
    operating_mode: str = SERVICE
    action_states: list[dict[str, Any]] = field(default_factory=list)
    battery_state: dict[str, Any] = field(default_factory=lambda: battery(0.0))
    errors: list[dict[str, Any]] = field(default_factory=list)
    information: list[dict[str, Any]] = field(default_factory=list)
    e_stop: str = "NONE"
    field_violation: bool = False
    agv_position: dict[str, Any] | None = None
    velocity: dict[str, float] | None = None
    new_base_request: bool = False


def state(headers: Headers, f: StateFields, now: float | None = None) -> dict[str, Any]:
    msg = headers.next("state", now)
    msg.update({
        "orderId": f.order_id, "orderUpdateId": f.order_update_id,
        "lastNodeId": f.last_node_id, "lastNodeSequenceId": f.last_node_sequence_id,
        "nodeStates": f.node_states, "edgeStates": f.edge_states,
        "driving": f.driving, "paused": f.paused, "newBaseRequest": f.new_base_request,
        "operatingMode": f.operating_mode, "actionStates": f.action_states,
        "batteryState": f.battery_state, "errors": f.errors, "information": f.information,
        "safetyState": {"eStop": f.e_stop, "fieldViolation": f.field_violation},
    })
    if f.agv_position is not None:
        msg["agvPosition"] = f.agv_position
    if f.velocity is not None:
        msg["velocity"] = f.velocity
    return msg


def node_state(node: Mapping[str, Any]) -> dict[str, Any]:
    """The `nodeStates` entry of an order's node (position kept, actions left out)."""
    out = {k: node[k] for k in ("nodeId", "sequenceId", "released")}
    if "nodeDescription" in node:
        out["nodeDescription"] = node["nodeDescription"]
    if "nodePosition" in node:
        out["nodePosition"] = {k: v for k, v in node["nodePosition"].items()
                               if k in ("x", "y", "theta", "mapId")}
    return out


def edge_state(edge: Mapping[str, Any]) -> dict[str, Any]:
    out = {k: edge[k] for k in ("edgeId", "sequenceId", "released")}
    if "edgeDescription" in edge:
        out["edgeDescription"] = edge["edgeDescription"]
    return out


def agv_action(action_type: str, description: str, scopes: Iterable[str],
               parameters: Iterable[tuple[str, str, str, bool]] = (),
               result: str = "") -> dict[str, Any]:
    """A factsheet `agvActions` entry; parameters as (key, valueDataType, description,
    optional)."""
    out: dict[str, Any] = {"actionType": action_type, "actionDescription": description,
                           "actionScopes": list(scopes)}
    params = [{"key": k, "valueDataType": t, "description": d, "isOptional": o}
              for k, t, d, o in parameters]
    if params:
        out["actionParameters"] = params
    if result:
        out["resultDescription"] = result
    return out


@dataclass
class FactsheetFields:
    """What a RAMP robot can say about itself in a factsheet."""

    series_name: str
    description: str
    speed_max: float
    length: float
    width: float
    height: float
    actions: list[dict[str, Any]]
    versions: dict[str, str] = field(default_factory=dict)
    localization: bool = False
    max_load_kg: float = 0.0
    state_interval: float = 30.0
    visualization_interval: float = 0.5


def factsheet(headers: Headers, f: FactsheetFields, now: float | None = None) -> dict[str, Any]:
    msg = headers.next("factsheet", now)
    msg.update({
        "typeSpecification": {
            "seriesName": f.series_name, "seriesDescription": f.description,
            "agvKinematic": "DIFF", "agvClass": "CARRIER", "maxLoadMass": f.max_load_kg,
            "localizationTypes": ["NATURAL"] if f.localization else [],
            "navigationTypes": ["AUTONOMOUS"] if f.localization else [],
        },
        "physicalParameters": {
            "speedMin": 0.0, "speedMax": f.speed_max, "accelerationMax": 1.0,
            "decelerationMax": 1.0, "heightMax": f.height, "width": f.width,
            "length": f.length,
        },
        "protocolLimits": {
            "maxStringLens": {"msgLen": 65536, "idLen": 64, "topicSerialLen": 64},
            "maxArrayLens": {"order.nodes": 64, "order.edges": 63, "instantActions": 16},
            "timing": {"minOrderInterval": 1.0, "minStateInterval": 0.1,
                       "defaultStateInterval": f.state_interval,
                       "visualizationInterval": f.visualization_interval},
        },
        "protocolFeatures": {
            "optionalParameters": [
                {"parameter": "state.agvPosition", "support": "SUPPORTED",
                 "description": "only robots with the autonomy know where they are"},
            ] if f.localization else [],
            "agvActions": f.actions,
        },
        "agvGeometry": {},
        "loadSpecification": {},
        "vehicleConfig": {"versions": [{"key": k, "value": v} for k, v in f.versions.items()]},
    })
    return msg


# -- master -> robot ------------------------------------------------------------------------------
def action(action_type: str, action_id: str, *, blocking: str = "HARD",
           parameters: Mapping[str, Any] | None = None) -> dict[str, Any]:
    return {"actionType": action_type, "actionId": action_id, "blockingType": blocking,
            "actionParameters": [{"key": k, "value": v} for k, v in (parameters or {}).items()]}


def instant_actions(headers: Headers, actions: list[dict[str, Any]],
                    now: float | None = None) -> dict[str, Any]:
    return {**headers.next("instantActions", now), "actions": actions}


def node(node_id: str, sequence_id: int, x: float | None = None, y: float | None = None, *,
         theta: float | None = None, released: bool = True,
         actions: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {"nodeId": node_id, "sequenceId": sequence_id, "released": released,
                           "actions": actions or []}
    if x is not None and y is not None:
        out["nodePosition"] = {"x": x, "y": y, "mapId": MAP_ID}
        if theta is not None:
            out["nodePosition"]["theta"] = theta
    return out


def edge(edge_id: str, sequence_id: int, start: str, end: str, *,
         released: bool = True) -> dict[str, Any]:
    return {"edgeId": edge_id, "sequenceId": sequence_id, "released": released,
            "startNodeId": start, "endNodeId": end, "actions": []}


def order(headers: Headers, order_id: str, nodes: list[dict[str, Any]],
          edges: list[dict[str, Any]] | None = None, *, update_id: int = 0,
          now: float | None = None) -> dict[str, Any]:
    """An order; with no `edges`, one released edge between each two nodes."""
    if edges is None:
        edges = [edge(f"{a['nodeId']}-{b['nodeId']}", a["sequenceId"] + 1, a["nodeId"],
                      b["nodeId"]) for a, b in itertools.pairwise(nodes)]
    return {**headers.next("order", now), "orderId": order_id, "orderUpdateId": update_id,
            "nodes": nodes, "edges": edges}


# -- parsing --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Action:
    action_type: str
    action_id: str
    blocking: str
    parameters: dict[str, Any]


def decode(payload: bytes) -> dict[str, Any]:
    """A JSON object from an MQTT payload; MessageError otherwise."""
    try:
        msg = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MessageError(f"not JSON: {exc}") from exc
    if not isinstance(msg, dict):
        raise MessageError("not a JSON object")
    return msg


def _need(obj: Mapping[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    if key not in obj:
        raise MessageError(f"{where}: {key} is missing")
    value = obj[key]
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise MessageError(f"{where}: {key} has the wrong type")
    return value


def parse_action(obj: Any, where: str = "action") -> Action:
    if not isinstance(obj, dict):
        raise MessageError(f"{where}: not an object")
    params: dict[str, Any] = {}
    raw = obj.get("actionParameters", [])
    if not isinstance(raw, list):
        raise MessageError(f"{where}: actionParameters is not a list")
    for i, p in enumerate(raw):
        if not isinstance(p, dict) or not isinstance(p.get("key"), str) or "value" not in p:
            raise MessageError(f"{where}: actionParameters[{i}] needs key and value")
        params[p["key"]] = p["value"]
    blocking = obj.get("blockingType", "HARD")
    if blocking not in ("NONE", "SOFT", "HARD"):
        raise MessageError(f"{where}: blockingType must be NONE, SOFT or HARD")
    return Action(_need(obj, "actionType", str, where), _need(obj, "actionId", str, where),
                  blocking, params)


def parse_instant_actions(msg: Mapping[str, Any]) -> list[Action]:
    actions = _need(msg, "actions", list, "instantActions")
    return [parse_action(a, f"instantActions.actions[{i}]") for i, a in enumerate(actions)]


@dataclass(frozen=True)
class OrderNode:
    node_id: str
    sequence_id: int
    released: bool
    x: float | None
    y: float | None
    theta: float | None
    actions: list[Action]
    raw: dict[str, Any]


@dataclass(frozen=True)
class Order:
    order_id: str
    update_id: int
    nodes: list[OrderNode]
    edges: list[dict[str, Any]]


def parse_order(msg: Mapping[str, Any]) -> Order:
    """The fields of an order the agent drives by; MessageError names the first bad one."""
    order_id = _need(msg, "orderId", str, "order")
    update_id = _need(msg, "orderUpdateId", int, "order")
    nodes_raw = _need(msg, "nodes", list, "order")
    edges = _need(msg, "edges", list, "order")
    if not nodes_raw:
        raise MessageError("order: nodes is empty")
    nodes = []
    for i, n in enumerate(nodes_raw):
        where = f"order.nodes[{i}]"
        if not isinstance(n, dict):
            raise MessageError(f"{where}: not an object")
        pos = n.get("nodePosition")
        x = y = theta = None
        if pos is not None:
            if not isinstance(pos, dict):
                raise MessageError(f"{where}.nodePosition: not an object")
            x = _number(pos, "x", where + ".nodePosition")
            y = _number(pos, "y", where + ".nodePosition")
            theta = _number(pos, "theta", where + ".nodePosition") if "theta" in pos else None
        acts = n.get("actions", [])
        if not isinstance(acts, list):
            raise MessageError(f"{where}: actions is not a list")
        nodes.append(OrderNode(_need(n, "nodeId", str, where), _need(n, "sequenceId", int, where),
                               bool(_need(n, "released", bool, where)), x, y, theta,
                               [parse_action(a, f"{where}.actions[{j}]")
                                for j, a in enumerate(acts)], dict(n)))
    for i, e in enumerate(edges):
        where = f"order.edges[{i}]"
        if not isinstance(e, dict):
            raise MessageError(f"{where}: not an object")
        for key in ("edgeId", "startNodeId", "endNodeId"):
            _need(e, key, str, where)
        _need(e, "sequenceId", int, where)
        _need(e, "released", bool, where)
    return Order(order_id, update_id, nodes, edges)


def _number(obj: Mapping[str, Any], key: str, where: str) -> float:
    value = _need(obj, key, (int, float), where)
    if isinstance(value, bool) or not math.isfinite(value):
        raise MessageError(f"{where}: {key} must be a finite number")
    return float(value)
