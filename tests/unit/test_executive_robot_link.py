"""The executive's link to the robot, against the real backend (the sim backplane moving an
empty arena) over TCP on a virtual clock: what the polls read, whose errors an activity
sees, when the watchdog is fed, and what an operator's takeover and a watchdog trip do."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from firmware_like.marte import MarteWorld
from ramp.autonomy.executive.robot import RobotLink
from ramp.autonomy.mcp_link import McpLink
from ramp.autonomy.odometry import Odometry
from ramp.simulation.backend import SimBackend
from ramp.statemachine import StatusKind


class Bench:
    def __init__(self) -> None:
        self.world = MarteWorld()
        self.backend = SimBackend(self.world)
        self.scheduler = self.backend.scheduler
        self.clock = self.backend.clock
        self.odometry = Odometry(now=self.clock.now())
        self.link = McpLink(self.backend.address, clock=self.clock, loop=self.scheduler,
                            heartbeat_s=None)
        self.robot = RobotLink(self.link, self.odometry)
        self.owners: list[str] = []
        self.trips: list[str] = []
        self.foreign: list[str] = []
        self.robot.on_owner = self.owners.append
        self.robot.on_trip = self.trips.append
        self.robot.on_foreign_owner = self.foreign.append
        self.scheduler.add_task("odometry", self.scheduler.rate_hz, self.odometry.tick)
        self.scheduler.add_task("link", self.scheduler.rate_hz, self.link.tick)
        self.scheduler.add_task("robot", 20.0, self.robot.tick)
        self.link.start()
        self.run(0.3)

    def run(self, seconds: float) -> None:
        self.scheduler.run_for(seconds)

    def operator(self) -> McpLink:
        op = McpLink(self.backend.address, clock=self.clock, loop=self.scheduler)
        self.scheduler.add_task("operator", self.scheduler.rate_hz, op.tick)
        op.start()
        return op

    def close(self) -> None:
        self.link.stop()
        self.backend.close()


@pytest.fixture
def bench() -> Iterator[Bench]:
    b = Bench()
    yield b
    b.close()


def test_polls_read_the_robot_and_tell_the_mission_who_holds_control(bench: Bench) -> None:
    bench.run(1.5)
    robot = bench.robot
    assert robot.owner == "none" and bench.owners and bench.owners[-1] == "none"
    assert robot.lift_pos == pytest.approx(0.0, abs=0.02)
    assert robot.load_kg == pytest.approx(0.0, abs=0.1)
    assert robot.buttons == (False, False)
    assert robot.watchdog_state == "idle" and robot.watchdog_timeout == 1.0


def test_idle_polls_are_too_rare_to_feed_the_watchdog_and_moving_ones_feed_it(
        bench: Bench) -> None:
    def polls_in(seconds: float) -> int:
        before = bench.link.stats["sent"]
        bench.run(seconds)
        return bench.link.stats["sent"] - before

    idle = polls_in(10.0)
    assert 7 <= idle <= 9  # every 1.25 x the 1 s watchdog timeout
    bench.robot.moving = True
    assert polls_in(10.0) >= 45  # every 0.2 s


def test_an_error_answer_is_the_current_activitys_problem_and_only_its(bench: Bench) -> None:
    robot = bench.robot
    robot.begin()
    robot.send("base:lf_wheel.vel=(300)")
    bench.run(0.1)
    problem = robot.problem()
    assert problem is not None and problem.kind is StatusKind.FAULT
    assert "bad_params" in problem.reason and "base:lf_wheel.vel=(300)" in problem.reason
    robot.begin()
    assert robot.problem() is None
    robot.send("base:lf_wheel.vel=(300)")  # answered after the next activity began
    robot.begin()
    bench.run(0.1)
    assert robot.problem() is None


def test_an_operator_takeover_is_seen_as_operator_and_stops_odometry(bench: Bench) -> None:
    robot = bench.robot
    robot.begin()
    robot.send("robot:control.acquire=(autonomy)")
    robot.drive(40, 0)
    bench.run(1.0)
    assert bench.odometry.moving and robot.problem() is None
    op = bench.operator()
    bench.run(0.2)
    op.send("robot:control.acquire=(operator)")
    bench.run(0.2)
    assert bench.world.duty("base.lf_wheel") == 0.0  # the acquire stopped the robot
    robot.drive(40, 0)
    bench.run(1.0)  # the answer, and the wheels' spin-down in odometry
    problem = robot.problem()
    assert problem is not None and problem.kind is StatusKind.OPERATOR
    assert "not_owner" in problem.reason
    assert not robot.moving and not bench.odometry.moving
    assert bench.owners[-1] == "operator" and bench.foreign[-1] == "operator"
    op.stop()


def test_a_refusal_by_an_interlock_is_handled_like_not_owner_naming_the_rule(
        bench: Bench) -> None:
    """MARTE's shipped chain_needs_ladder_down: the chain is refused with the bin up."""
    robot = bench.robot
    bench.world.lift_pos = 0.8
    bench.run(0.1)
    robot.begin()
    robot.moving = True
    robot.send("ble:chain.vel=(100)")
    bench.run(0.1)
    problem = robot.problem()
    assert problem is not None and problem.kind is StatusKind.OPERATOR
    assert problem.reason.startswith("interlocked: chain_needs_ladder_down is active")
    assert "ble:chain.vel=(100)" in problem.reason
    assert not robot.moving  # it stops meaning to move, as after not_owner
    assert bench.world.duty("ble.chain_left") == 0.0


def test_a_watchdog_trip_while_moving_is_reported_once(bench: Bench) -> None:
    robot = bench.robot
    robot.begin()
    robot.send("robot:control.acquire=(autonomy)")
    robot.send("robot:watchdog.timeout=(0.1)")  # shorter than the 0.2 s polls
    bench.run(0.5)
    robot.drive(30, 0)
    bench.run(2.0)
    assert robot.watchdog_state == "tripped"
    assert len(bench.trips) == 1 and "watchdog" in bench.trips[0]
    assert not robot.moving and not bench.odometry.moving
