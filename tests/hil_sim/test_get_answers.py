"""A get answer is formatted once and kept until the robot's state may have changed (README,
"Why a cached get answer is never stale"): every answer must still be the state of the moment,
whatever changed it (a tick, a command, a stop, a lost client, a fault)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

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


# -- the server's answers given again (`McpServer`: a repeated message, the version holding) --
def _connection(h: Harness, index: int = -1) -> Any:
    return list(h.sup.server.clients.values())[index]


def _until_held(h: Harness) -> None:
    """Pump the server until it has read the bytes sent and holds them as an unended line."""
    for _ in range(500):
        h.pump_io()
        if not _connection(h).splitter.empty:
            return
        time.sleep(0.001)
    raise AssertionError("the server never read the unended line")


def test_a_message_given_again_sees_another_clients_command(marte: SimHarness) -> None:
    watcher, driver = marte.connect(), marte.connect()
    first = watcher.ask("base:base.get=()")
    assert watcher.ask("base:base.get=()") == first  # the same version: the same answer
    assert driver.ask("base:lf_wheel.vel=(30)") == ""  # no tick in between
    assert rows(watcher.ask("base:base.get=()"))["base:lf_wheel.vel"] == "30"
    assert driver.ask("base:base.stop=()") == ""
    assert rows(watcher.ask("base:base.get=()"))["base:lf_wheel.vel"] == "0"


def test_a_known_message_that_ends_a_held_line_is_that_line(marte: SimHarness) -> None:
    c = marte.connect()
    known = c.ask("base:base.get=()")
    assert c.ask("base:base.get=()") == known
    c.send("base:ba")  # the start of a line, held by the server
    _until_held(marte)
    assert c.ask("base:base.get=()").startswith("robot:mcp.error=(")  # base:babase:...
    c.send("x" * 5000)  # longer than max_line: discarded as it arrives
    _until_held(marte)
    assert c.ask("base:base.get=()").startswith("robot:mcp.error=(too_long,")
    assert c.ask("base:base.get=()") == known
    assert c.ask("base:base.get=()\r\r") == known
    assert c.ask("base:base.get=()\r") == known


def test_a_known_message_read_before_its_newline_waits_for_it(marte: SimHarness) -> None:
    """A read of a kept message without its `\n` is an unended line, not the message: the
    answer comes once, when the `\n` arrives, and the next answers stay in step."""
    c = marte.connect()
    known = c.ask("base:base.get=()")
    assert c.ask("base:base.get=()") == known
    c.send("base:base.get=()")
    _until_held(marte)
    assert c.buf == b""
    c.send("\n")
    assert c.line() == known
    assert c.ask("base:lf_wheel.vel=(30)") == ""
    assert rows(c.ask("base:base.get=()"))["base:lf_wheel.vel"] == "30"


def test_messages_read_together_are_given_the_answers_of_their_moment(
        marte: SimHarness) -> None:
    c = marte.connect()
    known = c.ask("base:base.get=()")
    c.send("base:base.get=()\nbase:lf_wheel.vel=(30)\nbase:base.get=()\nbase:base.get=()\n")
    assert c.line() == known
    assert c.line() == ""
    after = c.line()
    assert rows(after)["base:lf_wheel.vel"] == "30"
    assert c.line() == after


def test_a_message_given_again_is_heard_by_the_watchdog(marte: SimHarness) -> None:
    """The commander only ever repeats a message another client sent first in the same
    tick: its answer is given again, and the commander still counts as heard."""
    primer, commander = marte.connect(), marte.connect()
    assert commander.ask("robot:watchdog.timeout=(0.3)") == ""
    assert commander.ask("base:base.drive=(40,40)") == ""
    for _ in range(10):  # 1.5 s: five of its own timeouts
        marte.advance(0.15)
        primer.ask("base:base.get=()")
        commander.ask("base:base.get=()")
    assert "robot:watchdog.state=(armed)" in primer.ask("robot:robot.get=()")
    marte.advance(0.5)  # silent now: the watchdog trips
    assert "robot:watchdog.state=(tripped)" in primer.ask("robot:robot.get=()")


def test_observers_see_every_message_given_again(marte: SimHarness) -> None:
    seen: list[tuple[str, bytes]] = []
    server = marte.sup.server
    server.on_message_in = lambda client, t, msg: seen.append(("in", bytes(msg)))
    server.on_message_out = lambda client, t, line: seen.append(("out", line))
    c = marte.connect()
    answers = [c.ask("base:base.get=()") for _ in range(3)]
    assert seen == [("in", b"base:base.get=()"), ("out", answers[0].encode())] * 3


def test_an_answer_that_depends_on_its_client_is_never_given_again(marte: SimHarness) -> None:
    a, b = marte.connect(), marte.connect()
    assert a.ask("robot:watchdog.timeout=(0.3)") == ""
    assert rows(a.ask("robot:robot.get=()"))["robot:watchdog.timeout"] == "0.3"
    assert rows(b.ask("robot:robot.get=()"))["robot:watchdog.timeout"] == "1.0"
    assert rows(a.ask("robot:robot.get=()"))["robot:watchdog.timeout"] == "0.3"
