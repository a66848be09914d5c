"""The fleet supervisor's view of its robots, built only from what they publish (SPEC 14).

An MQTT client (paho) subscribed to `uagv/v2/+/+/{connection,state,factsheet,visualization}`
keeps one `Tile` per robot: what it is (its factsheet), whether it is there (its connection
and the age of its last message), and what it is doing (its state). Nothing here knows a robot
type: a robot the page never heard of is a tile as soon as it speaks.

The supervisor's commands are VDA 5050 instant actions and orders on the robots' own topics:
**Stop all** sends `stopPause` to every robot it knows and measures, per robot, the time from
the publish to the first `state` that reports that action and `driving=false`.
"""

from __future__ import annotations

import itertools
import json
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ramp.fleet import vda5050 as v
from ramp.fleet.page.alerts import LEVELS, Alert, Board, robot_alerts

log = logging.getLogger("ramp.fleet.page")

TOPICS = ("connection", "state", "factsheet", "visualization")


@dataclass
class Tile:
    """One robot as the page shows it."""

    manufacturer: str
    serial: str
    connection: str = "UNKNOWN"
    last_seen: float = 0.0  # monotonic time of its last message
    factsheet: dict[str, Any] = field(default_factory=dict)
    state: dict[str, Any] = field(default_factory=dict)
    position: dict[str, Any] | None = None
    stop_sent_at: float | None = None
    stop_action: str | None = None
    stop_ms: float | None = None

    @property
    def actions(self) -> list[str]:
        """The actions its factsheet says it takes (instant and in orders)."""
        feats = self.factsheet.get("protocolFeatures", {})
        return sorted({str(a.get("actionType")) for a in feats.get("agvActions", [])})

    def alerts(self, now: float) -> list[Alert]:
        """Its alerts in the console's model (ramp.fleet.page.alerts)."""
        pending = (now - self.stop_sent_at if self.stop_sent_at is not None
                   and self.stop_ms is None else None)
        return robot_alerts(self.serial, self.connection,
                            now - self.last_seen if self.last_seen else None, self.state,
                            pending)

    def as_json(self, now: float, consoles: dict[str, str]) -> dict[str, Any]:
        spec = self.factsheet.get("typeSpecification", {})
        st = self.state
        battery = st.get("batteryState", {})
        unknown_charge = any(i.get("infoType") == "batteryChargeUnknown"
                             for i in st.get("information", []))
        info = {str(i.get("infoType")): str(i.get("infoDescription", ""))
                for i in st.get("information", [])}
        alerts = [{"level": LEVELS.get(str(e.get("errorLevel")), "warning"),
                   "type": str(e.get("errorType")), "text": str(e.get("errorDescription", ""))}
                  for e in st.get("errors", [])]
        if self.connection in ("CONNECTIONBROKEN", "OFFLINE"):
            alerts.insert(0, {"level": "error" if self.connection == "CONNECTIONBROKEN"
                              else "warning", "type": "connection",
                              "text": f"{self.connection}: no contact with its agent; the "
                                      "robot stops what its agent commanded"})
        return {
            "id": f"{self.manufacturer}/{self.serial}",
            "manufacturer": self.manufacturer, "serial": self.serial,
            "type": spec.get("seriesName") or spec.get("agvClass") or "?",
            "description": spec.get("seriesDescription", ""),
            "connection": self.connection,
            "age_s": round(now - self.last_seen, 1) if self.last_seen else None,
            "battery": None if unknown_charge or "batteryCharge" not in battery
            else battery["batteryCharge"],
            "voltage": battery.get("batteryVoltage"),
            "mode": st.get("operatingMode"), "driving": st.get("driving"),
            "paused": st.get("paused"),
            "owner": info.get("controlOwner", "").removeprefix("control is held by "),
            "mission": info.get("missionState", ""),
            "information": info, "alerts": alerts,
            "actions": self.actions, "can_mission": "rmcMission" in self.actions,
            "stop_ms": self.stop_ms,
            "stopping": self.stop_sent_at is not None and self.stop_ms is None,
            "console": consoles.get(self.serial),
        }


class FleetSupervisor:
    """The MQTT side of `ramp-fleet`; thread-safe (paho's thread feeds it, the page reads)."""

    def __init__(self, host: str, port: int, *, client_id: str = "ramp-fleet",
                 tls: dict[str, str] | None = None, consoles: dict[str, str] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        import paho.mqtt.client as mqtt

        self.host, self.port = host, port
        self.clock = clock
        self.consoles = dict(consoles or {})
        self.tiles: dict[tuple[str, str], Tile] = {}
        self.board = Board()
        self.lock = threading.Lock()
        self.connected = threading.Event()
        self._ids = itertools.count(1)
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id,
                                  protocol=mqtt.MQTTv311, clean_session=True)
        if tls is not None:
            self.client.tls_set(ca_certs=tls["ca"], certfile=tls["cert"], keyfile=tls["key"])
        self.client.reconnect_delay_set(min_delay=1, max_delay=4)
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = lambda *a, **k: self.connected.clear()
        self.client.on_message = self._on_message

    def start(self) -> None:
        self.client.connect_async(self.host, self.port, keepalive=5)
        self.client.loop_start()

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()

    # -- incoming -------------------------------------------------------------------------
    def _on_connect(self, client: Any, _u: Any, _f: Any, rc: Any, _p: Any = None) -> None:
        if rc.is_failure:
            log.warning("the broker %s:%d refused the page: %s", self.host, self.port, rc)
            return
        client.subscribe([(f"uagv/v2/+/+/{name}", 1) for name in TOPICS])
        self.connected.set()

    def _on_message(self, _client: Any, _u: Any, msg: Any) -> None:
        self.receive(str(msg.topic), bytes(msg.payload))

    def receive(self, topic: str, payload: bytes) -> None:
        """One message from the broker (also how tests feed it)."""
        parts = v.split_topic(topic)
        if parts is None:
            return
        manufacturer, serial, name = parts
        try:
            data = json.loads(payload)
        except (ValueError, UnicodeDecodeError):
            return
        if not isinstance(data, dict):
            return
        now = self.clock()
        with self.lock:
            tile = self.tiles.get((manufacturer, serial))
            if tile is None:  # a robot heard of for the first time: ask for its state now
                tile = self.tiles[(manufacturer, serial)] = Tile(manufacturer, serial)
                if name != "state":
                    self._instant(tile, "stateRequest")
            tile.last_seen = now
            if name == "connection":
                tile.connection = str(data.get("connectionState", "UNKNOWN"))
            elif name == "factsheet":
                tile.factsheet = data
            elif name == "visualization":
                tile.position = data.get("agvPosition")
            elif name == "state":
                tile.state = data
                if tile.connection in ("UNKNOWN", "OFFLINE", "CONNECTIONBROKEN"):
                    tile.connection = "ONLINE"
                self._stop_seen(tile, data, now)

    @staticmethod
    def _stop_seen(tile: Tile, state: dict[str, Any], now: float) -> None:
        """The first state that reports our stopPause and `driving=false` ends the timing."""
        if tile.stop_sent_at is None or tile.stop_ms is not None:
            return
        ours = any(a.get("actionId") == tile.stop_action for a in state.get("actionStates", []))
        if ours and state.get("driving") is False:
            tile.stop_ms = round((now - tile.stop_sent_at) * 1e3, 1)

    # -- commands ---------------------------------------------------------------------------
    def _instant(self, tile: Tile, action_type: str,
                 parameters: dict[str, Any] | None = None) -> str:
        action_id = f"ramp-fleet-{action_type}-{next(self._ids)}"
        headers = v.Headers(tile.manufacturer, tile.serial)
        msg = v.instant_actions(headers, [v.action(action_type, action_id,
                                                   parameters=parameters)])
        self.client.publish(headers.topic("instantActions"), json.dumps(msg), qos=1)
        return action_id

    def stop_all(self) -> list[str]:
        """`stopPause` to every robot known; the time to `driving=false` is measured."""
        with self.lock:
            tiles = list(self.tiles.values())
            for tile in tiles:
                tile.stop_sent_at, tile.stop_ms = self.clock(), None
                tile.stop_action = self._instant(tile, "stopPause")
        log.warning("Stop all: stopPause sent to %d robot(s)", len(tiles))
        return [t.serial for t in tiles]

    def pause(self, key: str, on: bool) -> bool:
        with self.lock:
            tile = self._tile(key)
            if tile is None:
                return False
            action_id = self._instant(tile, "stopPause" if on else "startPause")
            if on:
                tile.stop_sent_at, tile.stop_ms, tile.stop_action = self.clock(), None, action_id
            return True

    def mission(self, key: str) -> str | None:
        """An order of one node carrying `rmcMission` (the robot's own mission), or why not."""
        with self.lock:
            tile = self._tile(key)
            if tile is None:
                return "no such robot"
            if "rmcMission" not in tile.actions:
                return f"{tile.serial} does not list rmcMission in its factsheet (no autonomy)"
            headers = v.Headers(tile.manufacturer, tile.serial)
            n = next(self._ids)
            order = v.order(headers, f"ramp-fleet-mission-{n}", [v.node(
                "start", 0, actions=[v.action("rmcMission", f"ramp-fleet-rmc-{n}")])])
            self.client.publish(headers.topic("order"), json.dumps(order), qos=1)
            return None

    def _tile(self, key: str) -> Tile | None:
        manufacturer, _, serial = key.partition("/")
        return self.tiles.get((manufacturer, serial))

    def snapshot(self) -> dict[str, Any]:
        now = self.clock()
        connected = self.connected.is_set()
        with self.lock:
            ordered = [t for _, t in sorted(self.tiles.items())]
            tiles = [t.as_json(now, self.consoles) for t in ordered]
            raised = [a for t in ordered for a in t.alerts(now)]
            if not connected:
                raised.append(Alert("broker", "error", "No broker",
                                    f"The page has no connection to the broker at {self.host}:"
                                    f"{self.port}: what it shows is stale and Stop all cannot "
                                    "reach the robots. Check the broker; the page reconnects by "
                                    "itself."))
            self.board.update(raised, now)
            alerts = self.board.view(now)
        return {"broker": f"{self.host}:{self.port}", "connected": connected,
                "robots": tiles, "alerts": alerts}
