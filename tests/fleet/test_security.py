"""`ramp fleet init`'s set-up against a real Mosquitto: TLS with one certificate per robot
and supervisor, and the ACL: a robot publishing as another, or writing instant actions or
orders, reaches nobody; a robot cannot read another's orders; a client without a certificate
is refused. (MQTT 3.1.1 brokers drop a denied publish silently: each check publishes the
denied message, then an allowed marker from the same client, and asserts the marker arrives
and the denied message never does; the broker keeps one client's messages in order.)"""

from __future__ import annotations

import contextlib
import json
import ssl
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import paho.mqtt.client as mqtt
import pytest

from ramp.fleet import vda5050 as v
from ramp.fleet.broker import LocalBroker
from ramp.fleet.init import FleetFiles, acl_text, check_names
from tests.fleet_fixtures import Collector, tls_fleet, tls_of


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[FleetFiles, LocalBroker]]:
    with tls_fleet(tmp_path_factory.mktemp("fleet"), ["r1", "r2"], ["sup"]) as out:
        yield out


def publisher(files: FleetFiles, broker: LocalBroker, name: str) -> mqtt.Client:
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"pub-{name}")
    t = tls_of(files, name)
    c.tls_set(ca_certs=t["ca"], certfile=t["cert"], keyfile=t["key"])
    c.connect(broker.host, broker.port)
    c.loop_start()
    return c


def publish(c: mqtt.Client, topic: str, body: dict[str, Any]) -> None:
    c.publish(topic, json.dumps(body), qos=1).wait_for_publish(5)


def test_acl_confines_each_identity(fleet: tuple[FleetFiles, LocalBroker]) -> None:
    files, broker = fleet
    sup = Collector(broker.host, broker.port, ["uagv/v2/#"], client_id="sup-watch",
                    tls=tls_of(files, "sup"))
    r2 = Collector(broker.host, broker.port, [v.topic("RAMP", "r2", "instantActions"),
                                              v.topic("RAMP", "r2", "order")],
                   client_id="r2", tls=tls_of(files, "r2"))
    r1_spy = Collector(broker.host, broker.port, [v.topic("RAMP", "r2", "order")],
                       client_id="r1", tls=tls_of(files, "r1"))
    r1 = publisher(files, broker, "r1")
    boss = publisher(files, broker, "sup")
    try:
        # r1 publishes as r2, and sends r2 instant actions and an order: all dropped.
        publish(r1, v.topic("RAMP", "r2", "state"), {"who": "forged"})
        publish(r1, v.topic("RAMP", "r2", "instantActions"), {"who": "forged"})
        publish(r1, v.topic("RAMP", "r2", "order"), {"who": "forged"})
        publish(r1, v.topic("RAMP", "r1", "instantActions"), {"who": "self-order"})
        publish(r1, v.topic("RAMP", "r1", "state"), {"who": "marker"})
        sup.wait_for("/r1/state", lambda m: m["who"] == "marker")
        # The supervisor's order reaches r2, not r1 (which cannot read r2's orders).
        publish(boss, v.topic("RAMP", "r2", "order"), {"who": "boss"})
        publish(boss, v.topic("RAMP", "r2", "instantActions"), {"who": "boss"})
        r2.wait_for("/r2/instantActions", lambda m: m["who"] == "boss")
        r2.wait_for("/r2/order", lambda m: m["who"] == "boss")
        time.sleep(0.3)
        everything = [m for c in (sup, r2, r1_spy) for t in ("state", "instantActions", "order")
                      for m in c.json("/" + t)]
        assert not [m for m in everything if m["who"] in ("forged", "self-order")]
        assert r1_spy.json("/order") == []
    finally:
        for c in (r1, boss):
            c.loop_stop()
            c.disconnect()
        for col in (sup, r2, r1_spy):
            col.close()


def never_connects(c: mqtt.Client, broker: LocalBroker) -> bool:
    """True when the broker never accepts `c` (no CONNACK with success in 2 s)."""
    accepted: list[bool] = []
    c.on_connect = lambda _c, _u, _f, rc, _p=None: accepted.append(not rc.is_failure)
    try:
        c.connect(broker.host, broker.port)
        for _ in range(20):
            if c.loop(0.1) != mqtt.MQTT_ERR_SUCCESS:
                break
    except (ssl.SSLError, OSError):
        pass
    finally:
        with contextlib.suppress(Exception):
            c.disconnect()
    return not any(accepted)


def test_no_certificate_no_entry(fleet: tuple[FleetFiles, LocalBroker]) -> None:
    files, broker = fleet
    anon = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="anon")
    anon.tls_set(ca_certs=str(files.tls.ca))
    assert never_connects(anon, broker)
    plain = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="plain")
    assert never_connects(plain, broker)
    ok = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="r1-check")
    t = tls_of(files, "r1")
    ok.tls_set(ca_certs=t["ca"], certfile=t["cert"], keyfile=t["key"])
    assert not never_connects(ok, broker)  # the check itself can tell


def test_acl_text_and_names() -> None:
    text = acl_text(["marte-1"], ["ops"], "RAMP")
    assert "user marte-1\ntopic write uagv/v2/RAMP/marte-1/connection" in text
    assert "topic read uagv/v2/RAMP/marte-1/instantActions" in text
    assert "topic write uagv/v2/+/+/order" in text and "topic read uagv/v2/#" in text
    assert "marte-1/order\ntopic write" not in text
    assert check_names(["a", "a"], []) == ["'a' is named twice"]
    assert check_names(["ca"], []) and check_names(["x/y"], [])


def test_init_command_refuses_bad_names(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    from ramp.cli import main

    assert main(["fleet", "init", str(tmp_path / "f"), "--robots", "a/b"]) == 2
    assert "not a name" in capsys.readouterr().err
    assert not (tmp_path / "f").exists()


def test_the_agent_speaks_tls_with_its_own_identity(fleet: tuple[FleetFiles, LocalBroker],
                                                    tmp_path: Path) -> None:
    """A robot's agent configured by its `fleet.tls` reaches the TLS broker as r1 and is
    heard; the same agent calling itself r2 (another robot's topics) is heard by nobody."""
    import subprocess

    from tests.fleet_fixtures import start_agent
    from tests.harness import start_ramp, stop_process

    files, broker = fleet
    crt, key = files.clients["r1"]
    cfg = tmp_path / "r1.yaml"
    cfg.write_text(Path("ramp.yaml").read_text() + (
        f"\nfleet:\n  serial: r1\n  broker: {broker.address}\n"
        f"  tls: {{ca: {files.tls.ca}, cert: {crt}, key: {key}}}\n"))
    proc, host, port = start_ramp(["--sim", "--host", "127.0.0.1", "--port", "0"],
                                  stderr=subprocess.DEVNULL)
    sup = Collector(broker.host, broker.port, ["uagv/v2/#"], client_id="sup-tls",
                    tls=tls_of(files, "sup"))
    agent = start_agent(str(cfg), f"{host}:{port}", broker.address, "r1", str(tmp_path))
    try:
        sup.wait_for("/r1/connection", lambda m: m["connectionState"] == "ONLINE")
        sup.wait_for("/r1/state", lambda m: True)
        stop_process(agent)
        # r1's certificate, r2's serial: its connection, state and will go nowhere.
        agent = start_agent(str(cfg), f"{host}:{port}", broker.address, "r2", str(tmp_path))
        time.sleep(2.0)
        assert sup.json("/r2/state") == [] and sup.json("/r2/connection") == []
    finally:
        stop_process(agent)
        sup.close()
        stop_process(proc)


def test_init_again_adds_a_robot_and_keeps_the_ca(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from ramp.cli import main

    d = tmp_path / "fleet"
    assert main(["fleet", "init", str(d), "--robots", "m1", "--supervisors", "ops"]) == 0
    out = capsys.readouterr().out
    assert f"tls: {{ca: {d}/ca.crt, cert: {d}/m1.crt, key: {d}/m1.key}}" in out
    ca, m1 = (d / "ca.crt").read_bytes(), (d / "m1.crt").read_bytes()
    assert (d / "m1.key").stat().st_mode & 0o077 == 0
    conf = (d / "mosquitto.conf").read_text()
    assert "require_certificate true" in conf and "use_identity_as_username true" in conf
    assert "allow_anonymous false" in conf and f"acl_file {d}/acl" in conf
    assert main(["fleet", "init", str(d), "--robots", "m1", "m2", "--supervisors", "ops"]) == 0
    assert (d / "ca.crt").read_bytes() == ca and (d / "m1.crt").read_bytes() == m1
    assert "user m2" in (d / "acl").read_text() and (d / "m2.crt").exists()
