"""A get answer is formatted once and kept until the robot's state may have changed (README,
"Why a cached get answer is never stale"): every answer must still be the state of the moment,
whatever changed it (a tick, a command, a stop, a lost client, a fault)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.harness import Harness, SimHarness


@pytest.fixture
def marte() -> Iterator[SimHarness]:
    h = SimHarness()
    yield h
    h.close()


def rows(line: str) -> dict[str, str]:
    out = {}
    for part in line.split(")")[:-1]:
        key, value = part.split("=(")
        out[key] = value
    return out


def test_a_command_shows_in_the_next_get_of_the_same_tick(marte: SimHarness) -> None:
    c = marte.connect()
    first = c.ask("base:base.get=()")
    assert first == c.ask("base:base.get=()")  # nothing changed: the same answer
    assert c.ask("base:lf_wheel.vel=(30)") == ""  # no tick in between
    assert rows(c.ask("base:base.get=()"))["base:lf_wheel.vel"] == "30"
    assert c.ask("base:base.stop=()") == ""
    assert rows(c.ask("base:base.get=()"))["base:lf_wheel.vel"] == "0"


def test_readings_change_with_the_ticks_and_only_with_them(marte: SimHarness) -> None:
    c = marte.connect()
    assert c.ask("ble:lift.vel=(100)") == ""
    marte.advance(0.1)  # the command is on the (emulated) wire and the lift moving
    before = rows(c.ask("ble:ble.get=()"))["ble:lift.pos"]
    marte.world.step(1.0)  # the world moves, but no tick has sampled it yet
    assert rows(c.ask("ble:ble.get=()"))["ble:lift.pos"] == before
    marte.advance(0.02)
    after = rows(c.ask("ble:ble.get=()"))["ble:lift.pos"]
    assert float(after) > float(before) + 0.05


def test_a_lost_client_and_a_fault_show_at_once() -> None:
    h = Harness()
    try:
        driver, monitor = h.connect(), h.connect()
        assert driver.ask("demo:motor.vel=(40)") == ""
        assert "demo:motor.vel=(40)" in monitor.ask("demo:demo.get=()")
        driver.close()  # the feeder goes: every module stops, no tick needed
        assert "demo:motor.vel=(0)" in monitor.ask("demo:demo.get=()")
        assert monitor.ask("arm:motor.vel=(20)") == ""
        assert "arm:motor.vel=(20)" in monitor.ask("arm:arm.get=()")
        h.world.unplugged.add("io2")
        h.advance(0.02)  # the bus's tick finds it gone: the module faults and stops
        assert monitor.ask("arm:arm.get=()").startswith("arm:arm.error=(fault,")
        assert "robot:arm.state=(fault)" in monitor.ask("robot:robot.get=()")
    finally:
        h.close()


def test_robot_get_is_never_kept(marte: SimHarness) -> None:
    c = marte.connect()
    first = rows(c.ask("robot:robot.get=()"))["robot:robot.uptime"]
    marte.advance(0.05)
    assert rows(c.ask("robot:robot.get=()"))["robot:robot.uptime"] != first
