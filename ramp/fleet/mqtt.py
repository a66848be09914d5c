"""The agent's MQTT link (paho-mqtt 2): the will, the subscriptions, and an inbox.

paho's own network thread keeps the broker connection (keep-alive, reconnect with back-off);
nothing else runs there: each received message is appended to `inbox` (a deque, safe across
threads) and the agent's loop takes it from there, so every decision stays on the agent's one
thread and clock. `publish` is paho's, which is safe from any thread.

The will is `connection` = CONNECTIONBROKEN, retained (VDA 5050 6.4): the broker publishes
it when the agent vanishes. ONLINE is published (retained) on every connect, OFFLINE on an
orderly exit before the disconnect (which discards the will).
"""

from __future__ import annotations

import contextlib
import json
import logging
import threading
from collections import deque
from typing import Any

import paho.mqtt.client as mqtt

from ramp.fleet import vda5050 as v
from ramp.fleetconf import FleetTls

log = logging.getLogger("ramp.fleet.mqtt")


class MqttLink:
    """One robot's connection to the broker."""

    def __init__(self, headers: v.Headers, host: str, port: int, *,
                 tls: FleetTls | None = None, keepalive: int = 5) -> None:
        self.headers = headers
        self.host, self.port = host, port
        self.keepalive = keepalive
        self.inbox: deque[tuple[str, bytes]] = deque(maxlen=1024)
        self.connected = threading.Event()
        self.connects = 0
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2,
                                  client_id=f"ramp-agent-{headers.serial}",
                                  protocol=mqtt.MQTTv311, clean_session=True)
        if tls is not None:
            self.client.tls_set(ca_certs=str(tls.ca), certfile=str(tls.cert),
                                keyfile=str(tls.key))
        self.client.will_set(headers.topic("connection"),
                             json.dumps(v.connection(headers, v.CONNECTIONBROKEN)), qos=1,
                             retain=True)
        self.client.reconnect_delay_set(min_delay=1, max_delay=4)
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect
        self.client.on_message = self._on_message

    def start(self) -> None:
        """Connect in the background (returns at once; a broker that is down is retried)."""
        self.client.connect_async(self.host, self.port, keepalive=self.keepalive)
        self.client.loop_start()

    def publish(self, name: str, message: dict[str, Any], *, retain: bool = False,
                qos: int = 0) -> bool:
        """Publish on the robot's `name` topic; False while disconnected (not queued: a stale
        state is worth nothing, the next one is sent on reconnect)."""
        if not self.connected.is_set():
            return False
        info = self.client.publish(self.headers.topic(name), json.dumps(message), qos=qos,
                                   retain=retain)
        return info.rc == mqtt.MQTT_ERR_SUCCESS

    def close(self, offline: bool = True) -> None:
        """Orderly exit: OFFLINE (retained), then a clean disconnect (no will)."""
        if offline and self.connected.is_set():
            info = self.client.publish(self.headers.topic("connection"),
                                       json.dumps(v.connection(self.headers, v.OFFLINE)),
                                       qos=1, retain=True)
            with contextlib.suppress(RuntimeError, ValueError):
                info.wait_for_publish(timeout=2.0)
        self.client.disconnect()
        self.client.loop_stop()

    def _on_connect(self, client: mqtt.Client, _userdata: Any, _flags: Any, rc: Any,
                    _props: Any = None) -> None:
        if rc.is_failure:
            log.warning("broker %s:%d refused the connection: %s", self.host, self.port, rc)
            return
        self.connects += 1
        client.subscribe([(self.headers.topic("order"), 1),
                          (self.headers.topic("instantActions"), 1)])
        client.publish(self.headers.topic("connection"),
                       json.dumps(v.connection(self.headers, v.ONLINE)), qos=1, retain=True)
        log.info("connected to the broker at %s:%d", self.host, self.port)
        self.connected.set()
        self.inbox.append(("", b"connected"))  # tells the loop: publish state and factsheet

    def _on_disconnect(self, _client: mqtt.Client, _userdata: Any, _flags: Any, rc: Any,
                       _props: Any = None) -> None:
        if self.connected.is_set():
            log.warning("lost the broker at %s:%d (%s); retrying", self.host, self.port, rc)
        self.connected.clear()

    def _on_message(self, _client: mqtt.Client, _userdata: Any, msg: Any) -> None:
        self.inbox.append((msg.topic, bytes(msg.payload)))
