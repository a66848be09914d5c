"""The autonomy's command endpoint (ramp/autonomy/command.py) over a real loopback socket,
on a mission in a scripted world: the mission waits for rmcMission, a bad line is answered
in words, node tasks are refused without the executive's kit, and a client that commanded
the mission and vanishes leaves it held."""

from __future__ import annotations

import json
import socket
from typing import Any

from ramp.autonomy.command import WAITING_FOR_ORDER, CommandEndpoint
from tests.unit.mission_world import make_run


class Pose:
    x, y, yaw = 1.0, 2.0, 0.5


def ask(sock: socket.socket, ep: CommandEndpoint, line: bytes) -> dict[str, Any]:
    sock.sendall(line + b"\n")
    buf = b""
    while True:
        ep.tick(0.0, 0.0)
        try:
            buf += sock.recv(65536)
        except BlockingIOError:
            continue
        for raw in buf.split(b"\n")[:-1]:
            msg = json.loads(raw)
            if "re" in msg:
                return msg


def test_the_endpoint_holds_until_rmc_mission_and_after_its_commander_goes() -> None:
    run = make_run(start=False)
    t = [0.0]
    ep = CommandEndpoint(run.mission, pose=Pose, confidence=lambda: 0.8, now=lambda: t[0])
    run.mission.start(0.0)
    c = socket.create_connection(ep.address)
    c.setblocking(False)
    try:
        run.run(10.0)
        assert run.mission.state == "paused" and run.mission.held == WAITING_FOR_ORDER
        assert ask(c, ep, b"not json")["error"] == "not a JSON line"
        assert "without node tasks" in ask(c, ep, b'{"cmd": "goto", "x": 1}')["error"]
        status = ask(c, ep, b'{"cmd": "status"}')["status"]
        assert status["pose"] == {"x": 1.0, "y": 2.0, "yaw": 0.5} and not status["started"]
        t[0] = 10.0
        assert ask(c, ep, b'{"cmd": "rmcMission"}')["ok"]
        assert run.mission.context.budget.start_s == 10.0  # the run's time starts now
        run.run(40.0)
        assert run.mission.state not in ("paused",) and run.mission.has_control
    finally:
        c.close()
    ep.tick(40.0, 0.0)  # the commander is gone: the mission is held
    assert "disconnected" in (run.mission.held or "")
    run.run(45.0)
    assert run.mission.state == "paused"
    ep.close()
