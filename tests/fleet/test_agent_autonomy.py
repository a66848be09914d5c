"""The agent of a robot with the autonomy (`ramp sim mission --realtime --command-port`),
through a real Mosquitto: an order waits while an operator holds control, then runs the RMC
mission (SEMIAUTOMATIC, agvPosition with the localizer's confidence, the mission's state);
stopPause holds the mission and stops the robot; a killed agent leaves the mission held and
the robot stopped (the motion it commanded ends with it)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ramp.fleet import vda5050 as v
from ramp.fleet.broker import LocalBroker
from ramp.fleet.sim import Proc
from tests.fleet.schemas import validate
from tests.fleet_fixtures import Collector, start_agent
from tests.harness import REPO, ask_line, end_process, stop_process, value

SERIAL = "marte-auto"


class SimMission:
    def __init__(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "ramp.cli", "sim", "mission", "--realtime", "--port", "0",
             "--command-port", "0", "--duration", "300", "--seed", "1"], cwd=REPO,
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
            env={**os.environ, "PYTHONUNBUFFERED": "1"})
        # its announcements read as `ramp fleet sim` reads its robots'
        self.expect = Proc("ramp sim mission", self.proc).expect
        m = self.expect(r"MCP on ([\d.]+):(\d+)")
        self.mcp = (m.group(1), int(m.group(2)))
        m = self.expect(r"autonomy commands on ([\d.]+):(\d+)")
        self.commands = f"{m.group(1)}:{m.group(2)}"

    def close(self) -> None:
        if self.proc.poll() is None:
            end_process(self.proc, signal.SIGINT, 15)


@pytest.fixture
def sim() -> Iterator[SimMission]:
    s = SimMission()
    yield s
    s.close()


def info(state: dict[str, Any], kind: str) -> list[dict[str, Any]]:
    return [i for i in state.get("information", []) if i["infoType"] == kind]


def action(state: dict[str, Any], action_id: str) -> dict[str, Any] | None:
    return next((a for a in state["actionStates"] if a["actionId"] == action_id), None)


def test_order_runs_the_mission_and_a_dead_agent_stops_it(
        sim: SimMission, mosquitto: LocalBroker, tmp_path: Path) -> None:
    col = Collector(mosquitto.host, mosquitto.port, [f"uagv/v2/RAMP/{SERIAL}/#"])
    agent = start_agent("ramp.yaml", f"{sim.mcp[0]}:{sim.mcp[1]}", mosquitto.address, SERIAL,
                        str(tmp_path), "--autonomy", sim.commands)
    op = socket.create_connection(sim.mcp)
    try:
        sheet = col.wait_for("/factsheet", lambda m: True, timeout=20)
        assert "rmcMission" in {a["actionType"] for a in sheet["protocolFeatures"]["agvActions"]}
        col.wait_for("/state", lambda m: any("held" in i["infoDescription"]
                                             for i in info(m, "missionState")), timeout=20)
        # An operator holds control: the order waits, and says so.
        assert ask_line(op, "robot:control.acquire=(ana)") == ""
        h = v.Headers("RAMP", SERIAL)
        col.client.publish(v.topic("RAMP", SERIAL, "order"), json.dumps(v.order(
            h, "mission-1", [v.node("start", 0, actions=[v.action("rmcMission", "m1")])])))
        waiting = col.wait_for("/state", lambda m: m["operatingMode"] == "MANUAL" and any(
            "ana holds control" in i["infoDescription"] for i in info(m, "orderWaiting")))
        assert action(waiting, "m1")["actionStatus"] == "WAITING"
        assert waiting["orderId"] == "mission-1"
        validate("state", waiting)
        time.sleep(1.0)
        assert "ana" in ask_line(op, "robot:robot.get=()")
        # The operator hands back: the order runs the mission under the autonomy.
        assert ask_line(op, "robot:control.release=()") == ""
        running = col.wait_for("/state", lambda m: (action(m, "m1") or {}).get(
            "actionStatus") == "RUNNING" and m["operatingMode"] == "SEMIAUTOMATIC",
            timeout=20)
        assert running["lastNodeId"] == "start"
        validate("state", running)
        located = col.wait_for("/state", lambda m: "agvPosition" in m, timeout=40)
        assert 0.0 <= located["agvPosition"]["localizationScore"] <= 1.0
        assert located["agvPosition"]["mapId"] == "arena"
        vis = col.wait_for("/visualization", lambda m: "agvPosition" in m)
        validate("visualization", vis)
        # The fleet pauses the robot: the mission is held, the robot stands.
        col.client.publish(v.topic("RAMP", SERIAL, "instantActions"), json.dumps(
            v.instant_actions(h, [v.action("stopPause", "s1")])))
        held = col.wait_for("/state", lambda m: m["paused"] and not m["driving"] and any(
            "held" in i["infoDescription"] for i in info(m, "missionState")), timeout=10)
        validate("state", held)
        col.client.publish(v.topic("RAMP", SERIAL, "instantActions"), json.dumps(
            v.instant_actions(h, [v.action("startPause", "s2")])))
        col.wait_for("/state", lambda m: not m["paused"] and m["operatingMode"] ==
                     "SEMIAUTOMATIC" and not any("held" in i["infoDescription"]
                                                 for i in info(m, "missionState")), timeout=20)
        # The agent dies while the mission drives: the mission it commanded is held and the
        # robot stops.
        col.wait_for("/state", lambda m: m["driving"], timeout=60)
        agent.send_signal(signal.SIGKILL)
        agent.wait(5)
        col.wait_for("/connection", lambda m: m["connectionState"] == "CONNECTIONBROKEN",
                     timeout=20)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            get = ask_line(op, "base:base.get=()")
            if all(value(get, f"base:{w}_wheel.vel") == "0" for w in ("lf", "lb", "rf", "rb")):
                break
            time.sleep(0.1)
        time.sleep(3.0)  # held: nothing starts again
        get = ask_line(op, "base:base.get=()")
        assert all(value(get, f"base:{w}_wheel.vel") == "0" for w in ("lf", "lb", "rf", "rb"))
        with socket.create_connection(tuple(sim.commands.split(":")), timeout=5) as c:
            c.sendall(b'{"cmd": "status"}\n')
            reply = json.loads(c.makefile().readline())
        assert "disconnected" in (reply["status"]["held"] or "")
        for msg in col.json("/state"):
            validate("state", msg)
    finally:
        op.close()
        stop_process(agent)
        col.close()


def test_rmc_mission_as_an_instant_action(sim: SimMission, mosquitto: LocalBroker,
                                          tmp_path: Path) -> None:
    col = Collector(mosquitto.host, mosquitto.port, [f"uagv/v2/RAMP/{SERIAL}/#"])
    agent = start_agent("ramp.yaml", f"{sim.mcp[0]}:{sim.mcp[1]}", mosquitto.address, SERIAL,
                        str(tmp_path), "--autonomy", sim.commands)
    try:
        col.wait_for("/state", lambda m: bool(info(m, "missionState")), timeout=20)
        col.client.publish(v.topic("RAMP", SERIAL, "instantActions"), json.dumps(
            v.instant_actions(v.Headers("RAMP", SERIAL), [v.action("rmcMission", "i1")])))
        running = col.wait_for("/state", lambda m: (action(m, "i1") or {}).get(
            "actionStatus") == "RUNNING" and m["operatingMode"] == "SEMIAUTOMATIC",
            timeout=20)
        assert running["orderId"] == "" and running["nodeStates"] == []
        assert [a["actionId"] for a in running["actionStates"]].count("i1") == 1
        validate("state", running)
    finally:
        stop_process(agent)
        col.close()
