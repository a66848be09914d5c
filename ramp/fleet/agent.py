"""`ramp-fleet-agent`: one robot's bridge between its backend (MCP) and the fleet's broker
(MQTT, VDA 5050 2.1.0), on one scheduler loop and one clock.

Tasks on the loop: the MCP link (50 Hz), the robot poll (`robot.get` and every module's
`get`, 20 Hz), the MQTT inbox and the publications (50 Hz: `state` on every change and at
least every 30 s, `visualization` at 2 Hz), and the autonomy's link when the robot has one.

Supervisory, never in the motion path: the agent commands no motion of its own (stops, and
orders handed to the autonomy, which drives with its own planner); losing the broker changes
nothing on the robot; `stopPause` stops the robot through MCP at once and is written to disk
before anything else, so it survives agent, broker and robot restarts until `startPause`.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from ramp.fleet import mapping
from ramp.fleet import vda5050 as v
from ramp.fleet.mcplink import FleetMcpLink
from ramp.fleet.pause import PauseStore
from ramp.fleet.robot_view import RobotModel, RobotStatus
from ramp.mcp.messages import Response

log = logging.getLogger("ramp.fleet.agent")

STATE_EVERY_S = 30.0
VISUALIZATION_HZ = 2.0
POLL_HZ = 20.0
MAX_ACTION_STATES = 32
ERROR_KEEP_S = 60.0  # how long an orderError stays in state
REDESCRIBE_S = 2.0  # at most this often: describe again when a module comes back


class Publisher(Protocol):
    """What the agent needs of its MQTT link (`ramp.fleet.mqtt.MqttLink`)."""

    headers: v.Headers

    def publish(self, name: str, message: dict[str, Any], *, retain: bool = False,
                qos: int = 0) -> bool: ...


class AutonomyPort(Protocol):
    """What the agent needs of the autonomy (`ramp.fleet.autonomy_link.AutonomyLink`)."""

    address: str
    fault: str

    @property
    def connected(self) -> bool: ...

    @property
    def status(self) -> dict[str, Any]: ...

    def command(self, cmd: str, on_reply: Callable[[dict[str, Any]], None] | None = None,
                **args: Any) -> bool: ...

    def tick(self, now: float, dt: float) -> None: ...


@dataclass
class Identity:
    """The factsheet's description of the robot (config), beside what `describe` says."""

    series: str = "RAMP robot"
    speed_max: float = 0.5
    length: float = 1.2
    width: float = 0.75
    height: float = 0.8
    versions: dict[str, str] = field(default_factory=dict)


class Agent:
    """The bridge. `add_tasks(scheduler)`, then the scheduler's loop runs it."""

    def __init__(self, link: FleetMcpLink, mqtt: Publisher, pause: PauseStore, *,
                 now: Callable[[], float], autonomy: AutonomyPort | None = None,
                 identity: Identity | None = None,
                 inbox: deque[tuple[str, bytes]] | None = None) -> None:
        self.link = link
        self.mqtt = mqtt
        self.headers = mqtt.headers
        self.pause = pause
        self.now = now
        self.autonomy = autonomy
        self.identity = identity or Identity()
        self.inbox: deque[tuple[str, bytes]] = inbox if inbox is not None \
            else getattr(mqtt, "inbox", deque())
        self.model: RobotModel | None = None
        self.status: RobotStatus | None = None
        self._describing = False
        self._polling = False
        #: Counts poll answers: a decision on control waits for one sent after the question.
        self.status_seq = 0
        self._poll_now = False
        self._described_at = -math.inf
        self.actions: OrderedDict[str, dict[str, Any]] = OrderedDict()
        self._last_key = ""
        self._last_state_at = -math.inf
        self._last_vis_at = -math.inf
        self._state_due = True
        self._factsheet_due = True
        #: The order runner (ramp.fleet.orders.Orders) of a robot with the autonomy.
        self.orders: Any = None
        #: orderError / validationError entries with the time they expire, newest last.
        self._order_errors: list[tuple[float, dict[str, Any]]] = []
        link.on_connect = self._on_backend
        link.on_lost_cb = self._on_backend_lost
        pause.load()
        if pause.paused:
            log.warning("the fleet paused this robot (%s): it stays paused until startPause",
                        pause.reason or "stopPause")

    # -- scheduling ---------------------------------------------------------------------------
    def add_tasks(self, scheduler: Any) -> None:
        scheduler.add_task("fleet.mcp", scheduler.rate_hz, self.link.tick)
        scheduler.add_task("fleet.poll", scheduler.rate_at_most(POLL_HZ), self.poll)
        scheduler.add_task("fleet.mqtt", scheduler.rate_hz, self.service)
        if self.autonomy is not None:
            scheduler.add_task("fleet.autonomy", scheduler.rate_hz, self.autonomy.tick)

    # -- the backend --------------------------------------------------------------------------
    def _on_backend(self) -> None:
        """A new connection: nothing known of the robot until it describes itself."""
        self.model = None
        self._polling = False
        self._describe()

    def _describe(self) -> None:
        self._described_at = self.now()
        self._describing = True
        self.link.send("robot:robot.describe=()", self._on_robot_describe)

    def _on_backend_lost(self, reason: str) -> None:
        self._describing = self._polling = False
        self._state_due = True

    def _on_robot_describe(self, rows: list[Response], error: str) -> None:
        if error:
            return
        model = RobotModel()
        model.add_robot_rows(rows)
        if not model.modules:
            self.model = model
            self._describing = False
            return
        msg = "".join(f"{m}:{m}.describe=()" for m in model.modules)

        def got(rows: list[Response], error: str) -> None:
            if error:
                return
            for m in model.modules:
                model.add_module_rows(m, [r for r in rows if r.module == m])
            self.model = model
            self._describing = False
            self._factsheet_due = self._state_due = True
            self.poll(self.now(), 0.0)

        self.link.send(msg, got)

    def poll(self, now: float, dt: float) -> None:
        """One `robot.get` and every module's `get` in one message (one answer line)."""
        if self.model is None or self._polling or not self.link.connected:
            return
        msg = "robot:robot.get=()" + "".join(f"{m}:{m}.get=()" for m in self.model.modules)
        model = self.model

        def got(rows: list[Response], error: str) -> None:
            self._polling = False
            if error or self.model is not model:
                return
            self.status = RobotStatus.read(rows, model.modules)
            self.status_seq += 1
            missing = [m for m, st in self.status.module_states.items()
                       if st == "ok" and not model.functions.get(m)]
            if missing and now - self._described_at >= REDESCRIBE_S:
                # A module in fault or detached at describe time answered no rows; it is
                # back: learn its devices (its drive motors, battery, latches) now.
                log.info("module %s is back: describing the robot again", ", ".join(missing))
                self._describe()
            if self._poll_now:
                self._poll_now = False
                self._state_due = True

        self._polling = self.link.send(msg, got)

    def on_autonomy(self) -> None:
        """The autonomy's endpoint (re)connected: a fleet pause holds there too."""
        if self.pause.paused and self.autonomy is not None:
            self.autonomy.command("pause", reason="paused by the fleet (stopPause)")

    # -- instant actions ----------------------------------------------------------------------
    def _set_action(self, action: v.Action, status: str, result: str = "") -> None:
        self.actions[action.action_id] = v.action_state(action.action_id, action.action_type,
                                                        status, result)
        self.actions.move_to_end(action.action_id)
        while len(self.actions) > MAX_ACTION_STATES:
            self.actions.popitem(last=False)
        self._state_due = True

    def instant(self, action: v.Action) -> None:
        kind = action.action_type
        self._set_action(action, v.WAITING)
        if kind == "stopPause":
            self.stop_pause(action)
        elif kind == "startPause":
            was = self.pause.paused
            self.pause.set(False)
            if self.autonomy is not None:
                self.autonomy.command("resume")
            self._set_action(action, v.FINISHED, "resumed: the fleet's orders may drive again"
                             if was else "was not paused")
        elif kind == "cancelOrder":
            if self.orders is None:
                self._set_action(action, v.FAILED, "no order to cancel: this robot has no "
                                 "autonomy to run orders")
            else:
                ok, why = self.orders.cancel()
                self._set_action(action, v.FINISHED if ok else v.FAILED, why)
        elif kind == "rmcMission":
            if self.orders is None:
                self._set_action(action, v.FAILED, "this robot has no autonomy: it cannot run "
                                 "a mission")
            elif self.pause.paused:
                self._set_action(action, v.FAILED, "the robot is paused by the fleet "
                                 "(stopPause): send startPause first")
            else:
                self.orders.instant(action)
        elif kind == "stateRequest":
            self._set_action(action, v.FINISHED, "state sent")
        elif kind == "factsheetRequest":
            self._factsheet_due = True
            self._set_action(action, v.FINISHED, "factsheet sent")
        else:
            self._set_action(action, v.FAILED, f"unknown instant action {kind!r}; supported: "
                             + ", ".join(v.INSTANT_ACTIONS))

    def stop_pause(self, action: v.Action) -> None:
        """Hold the autonomy (so it sends no new motion after the stop), stop every module
        at once through MCP, then write the pause to disk (an fsync may take a while on an
        SD card; the stop is already out)."""

        def stopped(rows: list[Response], error: str) -> None:
            errors = [r for r in rows if r.prop == "error"]
            if error or errors:
                why = error or ", ".join(str(r.values) for r in errors)
                self._set_action(action, v.FAILED, f"paused, but the stop failed: {why}")
            else:
                self._set_action(action, v.FINISHED, "all motion stopped; paused until "
                                 "startPause")
            self._poll_now = True
            self._polling = False  # a poll sent before the stop would show motion
            self.poll(self.now(), 0.0)

        if self.autonomy is not None:
            self.autonomy.command("pause", reason="paused by the fleet (stopPause)")
        self._set_action(action, v.RUNNING, "stopping")
        sent = self.link.send("robot:robot.stop=()", stopped)
        self.pause.set(True, f"stopPause {action.action_id}")
        if self.orders is not None:
            self.orders.on_pause()
        if not sent:
            self._set_action(action, v.FAILED, "paused, but the robot's backend is not "
                             f"reachable to stop it ({self.link.fault})")

    # -- MQTT ---------------------------------------------------------------------------------
    def service(self, now: float, dt: float) -> None:
        """Handle what arrived, then publish what is due."""
        for _ in range(len(self.inbox)):
            topic, payload = self.inbox.popleft()
            try:
                self.handle(topic, payload)
            except Exception:
                log.exception("handling a message on %s failed; the agent goes on", topic)
        if self.orders is not None:
            self.orders.tick(now)
        self.publish_due(now)

    def handle(self, topic: str, payload: bytes) -> None:
        if topic == "":
            self._state_due = self._factsheet_due = True  # (re)connected to the broker
            return
        name = topic.rsplit("/", 1)[-1]
        try:
            msg = v.decode(payload)
            if name == "instantActions":
                for action in v.parse_instant_actions(msg):
                    self.instant(action)
            elif name == "order":
                if self.orders is None:
                    self.reject_order(msg, "this robot has no autonomy: it cannot run orders "
                                      "(it still answers instant actions)")
                elif self.pause.paused:
                    self.reject_order(msg, "the robot is paused by the fleet (stopPause): "
                                      "send startPause first")
                else:
                    self.orders.receive(msg)
        except v.MessageError as exc:
            log.warning("%s: %s", topic, exc)
            self.report(v.error("validationError", v.WARNING, f"{name}: {exc}",
                                {"topic": name}))

    def reject_order(self, msg: dict[str, Any], why: str) -> None:
        refs = {"orderId": str(msg.get("orderId", "")),
                "orderUpdateId": str(msg.get("orderUpdateId", ""))}
        self.report(v.error("orderError", v.WARNING, why, refs))

    def report(self, entry: dict[str, Any], keep_s: float = ERROR_KEEP_S) -> None:
        """An error about a message the robot received, shown in `state` for `keep_s`."""
        self._order_errors = [*self._order_errors[-7:], (self.now() + keep_s, entry)]
        self._state_due = True

    def clear_order_errors(self) -> None:
        self._order_errors.clear()
        self._state_due = True

    def publish_due(self, now: float) -> None:
        if self._factsheet_due and self.model is not None and \
                self.mqtt.publish("factsheet", self.factsheet(), retain=True, qos=1):
            self._factsheet_due = False
        fields = self.state_fields()
        key = json.dumps(_change_key(fields), sort_keys=True, default=str)
        due = key != self._last_key or self._state_due or \
            now - self._last_state_at >= STATE_EVERY_S
        if due and self.mqtt.publish("state", v.state(self.headers, fields, time.time())):
            self._last_key, self._last_state_at, self._state_due = key, now, False
        if now - self._last_vis_at >= 1.0 / VISUALIZATION_HZ:
            self._last_vis_at = now
            self.mqtt.publish("visualization", v.visualization(
                self.headers, fields.agv_position, fields.velocity, time.time()))

    # -- the mapping --------------------------------------------------------------------------
    def state_fields(self) -> v.StateFields:
        f = v.StateFields(paused=self.pause.paused,
                          action_states=list(self.actions.values()))
        now = self.now()
        self._order_errors = [(t, e) for t, e in self._order_errors if t > now]
        f.errors = [e for _, e in self._order_errors]
        model, status = self.model, self.status
        if not self.link.connected or model is None or status is None:
            f.errors.append(v.error("backendUnreachable", v.FATAL,
                                    f"the robot's backend at {self.link.address} does not "
                                    f"answer ({self.link.fault or 'starting'}); its state is "
                                    "unknown"))
            f.information.append(v.info("batteryChargeUnknown", "the backend is unreachable"))
        else:
            f.battery_state, info = mapping.battery_state(model, status)
            f.information += info + mapping.interlock_info(model, status)
            f.errors += mapping.errors(model, status)
            f.e_stop, f.field_violation = mapping.safety(model, status)
            f.driving = status.driving(model)
            running = self.orders is not None and self.orders.running
            f.operating_mode = mapping.operating_mode(status.owner, running)
            f.information.append(v.info("controlOwner", f"control is held by {status.owner}",
                                        {"owner": status.owner}))
        if self.pause.paused:
            f.information.append(v.info("fleetPause", "paused by the fleet (stopPause): the "
                                        "autonomy is paused and orders are refused until "
                                        "startPause"))
        if self.orders is not None:
            self.orders.fill(f)
        return f

    def factsheet(self) -> dict[str, Any]:
        model = self.model or RobotModel()
        actions = [v.agv_action(a, _INSTANT_TEXT[a], ["INSTANT"]) for a in v.INSTANT_ACTIONS]
        if self.orders is not None:
            actions += self.orders.factsheet_actions()
        versions = dict(self.identity.versions)
        for m in model.modules:
            devices = sorted({d for d, _, _ in model.properties.get(m, [])}
                             | {d for d, _, _ in model.functions.get(m, [])} - {m})
            versions[f"module.{m}"] = " ".join(devices)
        return v.factsheet(self.headers, v.FactsheetFields(
            self.identity.series,
            f"RAMP robot with modules {', '.join(model.modules) or 'none'}"
            + ("; with the autonomy" if self.orders is not None else "; no autonomy"),
            self.identity.speed_max, self.identity.length, self.identity.width,
            self.identity.height, actions, versions, localization=self.orders is not None,
            state_interval=STATE_EVERY_S, visualization_interval=1.0 / VISUALIZATION_HZ),
            time.time())


_INSTANT_TEXT = {
    "stopPause": "stop all motion now and stay paused (the autonomy paused, orders refused) "
                 "until startPause; kept across restarts",
    "startPause": "end the fleet's pause",
    "cancelOrder": "stop the running order (the robot stops where it is)",
    "stateRequest": "publish state now",
    "factsheetRequest": "publish the factsheet now",
}


def _change_key(f: v.StateFields) -> dict[str, Any]:
    """What makes a new `state` worth sending: all but the position, velocity and the
    battery's small drift (the charge counts in whole per cent)."""
    return {"order": (f.order_id, f.order_update_id, f.last_node_id, f.last_node_sequence_id),
            "nodes": [n["nodeId"] for n in f.node_states],
            "edges": [e["edgeId"] for e in f.edge_states],
            "driving": f.driving, "paused": f.paused, "mode": f.operating_mode,
            "actions": f.action_states, "errors": f.errors,
            "info": [i for i in f.information if i["infoType"] not in ("missionProgress",)],
            "charge": round(f.battery_state.get("batteryCharge", 0.0)),
            "safety": (f.e_stop, f.field_violation)}
