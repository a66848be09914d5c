"""LocalBroker: a real mosquitto that starts, carries messages, stops and comes back."""

from __future__ import annotations

from ramp.fleet.broker import LocalBroker, accepts, mosquitto_conf
from tests.fleet_fixtures import Collector


def test_broker_carries_a_message_and_comes_back_on_its_port(mosquitto: LocalBroker) -> None:
    import paho.mqtt.client as mqtt

    col = Collector(mosquitto.host, mosquitto.port, ["t/#"])
    pub = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
    pub.connect(mosquitto.host, mosquitto.port)
    pub.loop_start()
    pub.publish("t/a", b'{"n": 1}', qos=1).wait_for_publish(5)
    assert col.wait_for("t/a", lambda m: m["n"] == 1)
    pub.loop_stop()
    pub.disconnect()
    col.close()
    port = mosquitto.port
    mosquitto.stop()
    assert not accepts(mosquitto.host, port)
    mosquitto.start()
    assert mosquitto.port == port and accepts(mosquitto.host, port)


def test_plain_config_is_anonymous_on_loopback_only() -> None:
    text = mosquitto_conf(1883)
    assert "listener 1883 127.0.0.1" in text and "allow_anonymous true" in text
    assert "require_certificate" not in text
