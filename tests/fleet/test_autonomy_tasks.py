"""The autonomy's node tasks (ramp/autonomy/executive/tasks.py) through its command endpoint,
on a simulated MARTE on the virtual clock: `goto` into the digging region (the 3D scan
first, then the mission's planner and follower), `dig` there, `dump` at the collector (the
bin's load is delivered); what is refused, and why; `pause`/`resume` and `cancel` stop the
robot."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest

from ramp.autonomy.command import WAITING_FOR_ORDER, CommandEndpoint
from tests.fleet.virtual_robot import VirtualRobot

ENDED = ("done", "failed", "cancelled")


@pytest.fixture(scope="module")
def robot() -> Iterator[VirtualRobot]:
    r = VirtualRobot(seed=1)
    yield r
    r.close()


def ask(ep: CommandEndpoint, **cmd: object) -> dict[str, object]:
    return ep.handle(None, cmd)


WHEELS = ("base.lf_wheel", "base.lb_wheel", "base.rf_wheel", "base.rb_wheel")


def wheels_still(robot: VirtualRobot) -> bool:
    return all(robot.world.duty(w) == 0.0 for w in WHEELS)


def near(robot: VirtualRobot, x: float, y: float, tol: float = 0.15) -> bool:
    """The robot's true position (the world's, not the autonomy's estimate)."""
    t = robot.world.truth()
    return abs(t["x"] - x) < tol and abs(t["y"] - y) < tol


def test_goto_dig_and_dump_run_the_missions_own_steps(robot: VirtualRobot) -> None:
    ep = robot.endpoint
    assert "outside the arena" in str(ask(ep, cmd="goto", x=8.0, y=1.0)["error"])
    assert "finite number" in str(ask(ep, cmd="goto", x="far", y=1.0)["error"])
    assert "needs x and y" in str(ask(ep, cmd="goto", x=1.0)["error"])
    # Inside the start region, before any obstacle map: the start region's planner.
    assert ask(ep, cmd="goto", x=0.75, y=1.4, theta=0.0, id="n1")["ok"]
    assert "cancel it first" in str(ask(ep, cmd="dig", id="d0")["error"])
    assert "node task runs" in str(ask(ep, cmd="rmcMission")["error"])
    robot.run_until(lambda: robot.task().get("state") in ENDED)
    assert robot.task()["state"] == "done", robot.task()
    assert near(robot, 0.75, 1.4), robot.world.truth()
    # Digging outside the digging region fails and says why.
    assert ask(ep, cmd="dig", seconds=5, id="d1")["ok"]
    robot.run_until(lambda: robot.task().get("state") in ENDED)
    assert robot.task()["state"] == "failed"
    assert "outside the digging region" in robot.task()["reason"]
    # Into the digging region: the 3D scan first, then the mission's planner.
    steps: list[str] = []

    def watch() -> bool:
        t = robot.task()
        if t.get("step") and (not steps or steps[-1] != t["step"]):
            steps.append(t["step"])
        return t.get("state") in ENDED

    assert ask(ep, cmd="goto", x=3.9, y=1.0, theta=0.0, id="n2")["ok"]
    robot.run_until(watch)
    assert robot.task()["state"] == "done", robot.task()
    assert steps[-4:] == ["prepare_for_scan", "scan_for_obstacles", "detect_obstacles",
                          "goto"]
    assert near(robot, 3.9, 1.0), robot.world.truth()
    assert robot.world.truth()["collisions"] == 0 and robot.world.truth()["crater_entries"] == 0
    assert ask(ep, cmd="dig", seconds=8, id="d2")["ok"]
    robot.run_until(lambda: robot.task().get("state") in ENDED)
    assert robot.task()["state"] == "done", robot.task()
    assert "kg in the bin" in robot.task()["reason"]
    assert float(ep.status()["bin_kg"]) > 1.0  # type: ignore[arg-type]
    steps.clear()
    assert ask(ep, cmd="dump", id="u1")["ok"]
    robot.run_until(watch)
    assert robot.task()["state"] == "done", robot.task()
    assert steps[-5:] == ["plan_path_home", "cross_home", "dock", "deposit", "decouple"]
    assert float(ep.status()["delivered_kg"]) > 1.0  # type: ignore[arg-type]
    assert robot.world.delivered_kg > 1.0  # into the collector, says the referee
    assert near(robot, 0.9, 1.94, tol=0.2), robot.world.truth()
    assert ep.status()["held"] is not None  # the mission stayed out of the way


def test_pause_resume_and_cancel_stop_the_robot(robot: VirtualRobot) -> None:
    ep = robot.endpoint
    assert ask(ep, cmd="goto", x=2.6, y=1.2, theta=3.14, id="n3")["ok"]
    robot.run_until(lambda: robot.task().get("step") == "goto" and not wheels_still(robot))
    assert ask(ep, cmd="pause", reason="stopPause s1")["ok"]
    assert robot.task()["state"] == "held" and "stopPause" in robot.task()["reason"]
    robot.run_until(lambda: wheels_still(robot), sim_s=1.0)
    here, since = robot.world.truth(), robot.clock.now()
    robot.run_until(lambda: robot.clock.now() > since + 3.0 or not wheels_still(robot))
    assert wheels_still(robot) and near(robot, here["x"], here["y"], tol=0.02)
    assert ask(ep, cmd="resume")["ok"]
    assert robot.task()["state"] == "running"
    assert ep.status()["held"] == WAITING_FOR_ORDER  # the mission stays out of the way
    robot.run_until(lambda: robot.task().get("step") == "goto" and not wheels_still(robot))
    assert ask(ep, cmd="cancel", reason="order o1 cancelled")["ok"]
    assert robot.task()["state"] == "cancelled"
    robot.run_until(lambda: wheels_still(robot), sim_s=1.0)


def test_an_operator_who_takes_control_makes_the_task_wait(robot: VirtualRobot) -> None:
    ep = robot.endpoint
    assert ask(ep, cmd="goto", x=2.0, y=2.8, theta=0.0, id="n4")["ok"]
    robot.run_until(lambda: robot.task().get("step") == "goto" and not wheels_still(robot))
    with socket.create_connection(robot.mcp) as op:
        op.sendall(b"robot:control.acquire=(ana)\n")
        robot.run_until(lambda: robot.task().get("state") == "waiting")
        assert "ana holds control" in robot.task()["reason"] or "not_owner" in \
            robot.task()["reason"], robot.task()
        robot.run_until(lambda: wheels_still(robot), sim_s=1.0)
        since = robot.clock.now()
        robot.run_until(lambda: robot.clock.now() > since + 3.0)
        assert robot.task()["state"] == "waiting" and wheels_still(robot)
        op.sendall(b"robot:control.release=()\n")
        robot.run_until(lambda: robot.task().get("state") in ENDED)
        op.recv(65536)
    assert robot.task()["state"] == "done", robot.task()
    assert near(robot, 2.0, 2.8), robot.world.truth()
