"""The agent against a real backend (`ramp run --sim`) and a real Mosquitto: what it
publishes validates against the official schemas, stopPause stops a driving robot and holds
across an agent restart, a robot without the autonomy refuses an order with an orderError and
still answers instant actions, the last will, OFFLINE, and the broker's loss and return."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ramp.fleet import vda5050 as v
from ramp.fleet.broker import LocalBroker
from tests.fleet.schemas import validate
from tests.fleet_fixtures import Collector, start_agent
from tests.harness import ask_line, start_ramp, stop_process, value

SERIAL = "marte-t1"


@pytest.fixture
def robot() -> Iterator[tuple[str, int]]:
    proc, host, port = start_ramp(["--sim", "--host", "127.0.0.1", "--port", "0"],
                                  stderr=subprocess.DEVNULL)
    yield host, port
    stop_process(proc)


@pytest.fixture
def master(mosquitto: LocalBroker) -> Iterator[Collector]:
    col = Collector(mosquitto.host, mosquitto.port, [f"uagv/v2/RAMP/{SERIAL}/#"])
    yield col
    col.close()


def send(col: Collector, name: str, msg: dict[str, Any]) -> None:
    col.client.publish(v.topic("RAMP", SERIAL, name), json.dumps(msg), qos=1)


def run_agent(robot: tuple[str, int], broker: LocalBroker, state_dir: Path) -> Any:
    return start_agent("ramp.yaml", f"{robot[0]}:{robot[1]}", broker.address, SERIAL,
                       str(state_dir))


def test_messages_validate_and_stop_pause_holds(robot: tuple[str, int], mosquitto: LocalBroker,
                                                master: Collector, tmp_path: Path) -> None:
    agent = run_agent(robot, mosquitto, tmp_path)
    try:
        master.wait_for("/connection", lambda m: m["connectionState"] == "ONLINE")
        sheet = master.wait_for("/factsheet", lambda m: True)
        validate("factsheet", sheet)
        kinds = {a["actionType"] for a in sheet["protocolFeatures"]["agvActions"]}
        assert {"stopPause", "startPause", "cancelOrder", "stateRequest",
                "factsheetRequest"} <= kinds and "rmcMission" not in kinds
        # The first states may come before the agent has heard its backend (SERVICE, with a
        # backendUnreachable error and no battery reading): wait for one that has.
        state = master.wait_for("/state", lambda m: m["operatingMode"] == "SERVICE" and not any(
            e["errorType"] == "backendUnreachable" for e in m["errors"]))
        assert state["batteryState"]["batteryVoltage"] > 10
        # An operator drives the robot (and keeps feeding the watchdog).
        op = socket.create_connection(robot)
        assert ask_line(op, "robot:control.acquire=(ana)base:base.drive=(40,0)") == ""
        moving = master.wait_for("/state", lambda m: m["driving"])
        assert moving["operatingMode"] == "MANUAL"
        h = v.Headers("RAMP", SERIAL)
        t0 = time.monotonic()
        send(master, "instantActions", v.instant_actions(h, [v.action("stopPause", "p1")]))
        stopped = master.wait_for("/state", lambda m: not m["driving"] and m["paused"])
        elapsed = time.monotonic() - t0
        assert elapsed < 2.0
        assert value(ask_line(op, "base:base.get=()"), "base:lf_wheel.vel") == "0"
        done = master.wait_for("/state", lambda m: any(
            a["actionId"] == "p1" and a["actionStatus"] == "FINISHED" for a in m["actionStates"]))
        validate("state", stopped)
        validate("state", done)
        # A robot without the autonomy: an order is refused with an orderError, and instant
        # actions still work.
        send(master, "order", v.order(h, "o1", [v.node("n1", 0, 2.0, 1.0)]))
        refused = master.wait_for("/state", lambda m: any(
            e["errorType"] == "orderError" for e in m["errors"]))
        err = next(e for e in refused["errors"] if e["errorType"] == "orderError")
        assert "autonomy" in err["errorDescription"]
        send(master, "instantActions", v.instant_actions(h, [v.action("rmcMission", "m0")]))
        no_mission = master.wait_for("/state", lambda m: any(
            a["actionId"] == "m0" and a["actionStatus"] == "FAILED" for a in m["actionStates"]))
        assert "no autonomy" in next(a["resultDescription"] for a in no_mission["actionStates"]
                                     if a["actionId"] == "m0")
        validate("state", refused)
        # The pause is kept across an agent restart.
        stop_process(agent)
        master.wait_for("/connection", lambda m: m["connectionState"] == "OFFLINE")
        agent = run_agent(robot, mosquitto, tmp_path)
        n = len(master.json("/state"))
        again = master.wait_for("/state", lambda m: master.json("/state").index(m) >= n
                                and m["paused"])
        assert again["paused"]
        send(master, "instantActions", v.instant_actions(h, [v.action("startPause", "p2"),
                                                            v.action("stateRequest", "p3")]))
        master.wait_for("/state", lambda m: not m["paused"] and any(
            a["actionId"] == "p3" and a["actionStatus"] == "FINISHED" for a in m["actionStates"]))
        for kind in ("connection", "visualization"):
            for msg in master.json("/" + kind)[-3:]:
                validate(kind, msg)
        for msg in master.json("/state"):
            validate("state", msg)
        op.close()
    finally:
        stop_process(agent)


def test_last_will_and_broker_return(robot: tuple[str, int], mosquitto: LocalBroker,
                                     master: Collector, tmp_path: Path) -> None:
    agent = run_agent(robot, mosquitto, tmp_path)
    try:
        master.wait_for("/state", lambda m: True)
        send(master, "instantActions", v.instant_actions(v.Headers("RAMP", SERIAL), [
            v.action("stopPause", "b1")]))
        master.wait_for("/state", lambda m: m["paused"])
        # The broker goes away and comes back: the agent reconnects and says ONLINE again,
        # and the robot is still paused.
        mosquitto.stop()
        time.sleep(0.5)
        master.close()
        mosquitto.start()
        col = Collector(mosquitto.host, mosquitto.port, [f"uagv/v2/RAMP/{SERIAL}/#"])
        col.wait_for("/connection", lambda m: m["connectionState"] == "ONLINE", timeout=15)
        col.wait_for("/state", lambda m: not m["driving"] and m["paused"], timeout=15)
        # The agent is killed: the broker publishes its will, retained.
        agent.send_signal(signal.SIGKILL)
        agent.wait(5)
        will = col.wait_for("/connection",
                            lambda m: m["connectionState"] == "CONNECTIONBROKEN", timeout=20)
        validate("connection", will)
        col.close()
        late = Collector(mosquitto.host, mosquitto.port, [f"uagv/v2/RAMP/{SERIAL}/connection"])
        assert late.wait_for("/connection", lambda m: True)["connectionState"] == \
            "CONNECTIONBROKEN"
        late.close()
    finally:
        stop_process(agent)






def test_scout_is_mapped_from_its_own_describe(mosquitto: LocalBroker, tmp_path: Path) -> None:
    """Another robot, no fleet code for it: two wheels drive, the arm does not, the bumper's
    interlock is an error in state."""
    proc, host, port = start_ramp(["--sim", "--config", "examples/robots/scout.yaml",
                                   "--host", "127.0.0.1", "--port", "0"],
                                  stderr=subprocess.DEVNULL)
    col = Collector(mosquitto.host, mosquitto.port, ["uagv/v2/RAMP/scout-1/#"])
    agent = start_agent("examples/robots/scout.yaml", f"{host}:{port}", mosquitto.address,
                        "scout-1", str(tmp_path))
    op = socket.create_connection((host, port))
    try:
        sheet = col.wait_for("/factsheet", lambda m: True)
        versions = {e["key"]: e["value"] for e in sheet["vehicleConfig"]["versions"]}
        assert "left_wheel" in versions["module.base"] and "module.arm" in versions
        validate("factsheet", sheet)
        assert ask_line(op, "base:base.drive=(30,0)") == ""
        col.wait_for("/state", lambda m: m["driving"] and m["operatingMode"] == "SERVICE")
        ask_line(op, "base:base.stop=()sim:input.set=(base,bumper_left,1)")
        bumped = col.wait_for("/state", lambda m: any(
            e["errorType"] == "interlockActive" for e in m["errors"]))
        assert not bumped["driving"]
        validate("state", bumped)
    finally:
        op.close()
        stop_process(agent)
        col.close()
        stop_process(proc)


def test_a_module_in_fault_at_start_is_learnt_when_it_comes_back(
        robot: tuple[str, int], mosquitto: LocalBroker, tmp_path: Path) -> None:
    col = Collector(mosquitto.host, mosquitto.port, [f"uagv/v2/RAMP/{SERIAL}/#"])
    op = socket.create_connection(robot)
    ask_line(op, "sim:bus.unplug=(ble_motors)")
    agent = run_agent(robot, mosquitto, tmp_path)
    try:
        faulted = col.wait_for("/state", lambda m: any(
            e["errorType"] in ("moduleFault", "moduleDetached") for e in m["errors"]))
        validate("state", faulted)

        def ble_devices(m: dict[str, Any]) -> str:
            return next((e["value"] for e in m["vehicleConfig"]["versions"]
                         if e["key"] == "module.ble"), "")

        assert "lift" not in ble_devices(col.wait_for("/factsheet", lambda m: True))
        ask_line(op, "sim:bus.plug=(ble_motors)")
        col.wait_for("/factsheet", lambda m: "lift" in ble_devices(m), timeout=15)
        col.wait_for("/state", lambda m: not m["errors"], timeout=15)
    finally:
        op.close()
        stop_process(agent)
        col.close()
