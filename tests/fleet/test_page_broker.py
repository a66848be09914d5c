"""The page's supervisor on a real Mosquitto: over `ramp fleet init`'s TLS set-up with the
supervisor's certificate it sees a robot and its Stop all reaches it; under a robot's
certificate the broker's ACL drops its commands (the page is only as mighty as its identity).
And `ramp-fleet` / `ramp fleet sim` refuse bad command lines before starting anything."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from typing import Any

import paho.mqtt.client as mqtt
import pytest

from ramp.fleet import vda5050 as v
from ramp.fleet.broker import LocalBroker
from ramp.fleet.init import FleetFiles
from ramp.fleet.page.cli import main as page_main
from ramp.fleet.page.supervisor import FleetSupervisor, Tile
from tests.fleet_fixtures import Collector, tls_fleet, tls_of


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[FleetFiles, LocalBroker]]:
    with tls_fleet(tmp_path_factory.mktemp("fleet"), ["r1"], ["ops"]) as out:
        yield out


def robot_says_state(files: FleetFiles, broker: LocalBroker) -> mqtt.Client:
    """r1, under its own certificate, publishes one state (driving)."""
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="r1-pub")
    t = tls_of(files, "r1")
    c.tls_set(ca_certs=t["ca"], certfile=t["cert"], keyfile=t["key"])
    c.connect(broker.host, broker.port)
    c.loop_start()
    f = v.StateFields()
    f.driving = True
    c.publish(v.topic("RAMP", "r1", "state"), json.dumps(v.state(v.Headers("RAMP", "r1"), f)),
              qos=1).wait_for_publish(5)
    return c


def wait(pred: Any, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.05)
    return False


@pytest.mark.parametrize("identity, reaches", [("ops", True), ("r1", False)])
def test_the_page_commands_with_its_certificates_rights(
        fleet: tuple[FleetFiles, LocalBroker], identity: str, reaches: bool) -> None:
    files, broker = fleet
    listener = Collector(broker.host, broker.port, [v.topic("RAMP", "r1", "instantActions")],
                         client_id=f"r1-listen-{identity}", tls=tls_of(files, "r1"))
    sup = FleetSupervisor(broker.host, broker.port, client_id=f"page-{identity}",
                          tls=tls_of(files, identity))
    sup.start()
    robot = None
    try:
        assert sup.connected.wait(5), "the page never connected over TLS"
        robot = robot_says_state(files, broker)
        if identity == "ops":  # a supervisor reads every robot
            assert wait(lambda: [t["serial"] for t in sup.snapshot()["robots"]] == ["r1"])
        else:  # r1 may read only its own order/instantActions: it sees no robot
            time.sleep(0.5)
            assert sup.snapshot()["robots"] == []
            sup.tiles[("RAMP", "r1")] = Tile("RAMP", "r1")  # try to stop it all the same
        sup.stop_all()
        got = wait(lambda: any(a["actionType"] == "stopPause" for m in
                               listener.json("/instantActions") for a in m["actions"]),
                   timeout=3.0)
        assert got is reaches
    finally:
        if robot is not None:
            robot.loop_stop()
            robot.disconnect()
        sup.close()
        listener.close()


@pytest.mark.parametrize("argv, said", [
    (["--broker", "127.0.0.1:notaport"], "ramp-fleet:"),
    (["--broker", "127.0.0.1:1883", "--console", "scout-1"], "SERIAL=http"),
    (["--broker", "127.0.0.1:1883", "--console", "scout-1=ftp://x"], "SERIAL=http"),
    (["--broker", "127.0.0.1:1883", "--cert", "a.crt"], "go together"),
])
def test_ramp_fleet_refuses_a_bad_command_line(argv: list[str], said: str,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert page_main(argv) == 2
    assert said in capsys.readouterr().err


def test_fleet_sim_refuses_an_unknown_kind(capsys: pytest.CaptureFixture[str]) -> None:
    from ramp.cli import main

    assert main(["fleet", "sim", "--robots", "marte,rover"]) == 2
    err = capsys.readouterr().err
    assert "unknown rover" in err and "marte-noauto" in err
