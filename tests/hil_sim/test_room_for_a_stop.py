"""Always room for a stop (SPEC 2.2): with every slot taken, a newcomer evicts the client that
has been silent longest, if it has sent no complete message for 5 s and is neither the owner
nor the feeder; otherwise the newcomer gets `busy`. Idle connections used to keep an operator
out for as long as they stayed, with the robot driving.
"""

from __future__ import annotations

import logging

import pytest

from tests.harness import Harness
from tests.harness import TestClient as Client

YAML = """
server: {host: 127.0.0.1, port: 0, max_clients: 4}
watchdog: {timeout: 0.5}
buses:
  io: {driver: sim}
  io2: {driver: sim}
modules:
  demo: {motor: {bus: io}, lamp: {bus: io}}
  arm: {type: demo, motor: {bus: io2}, lamp: {bus: io2}}
"""


@pytest.fixture
def h() -> Harness:
    harness = Harness(YAML)
    yield harness
    harness.close()


def drive_for(h: Harness, driver: Client, seconds: float) -> None:
    """Let simulated time pass while the driver keeps the watchdog fed."""
    for _ in range(round(seconds / 0.1)):
        h.advance(0.1)
        assert driver.ask("") == ""


def closed_after_busy(c: Client) -> str:
    line = c.line()
    with pytest.raises(ConnectionError):
        c.line()
    return line


def test_a_newcomer_evicts_the_longest_silent_idle_client_and_can_stop_the_robot(
        h: Harness, caplog: pytest.LogCaptureFixture) -> None:
    idle = [h.connect() for _ in range(3)]
    driver = h.connect()
    assert driver.ask("demo:motor.vel=(50)") == ""
    drive_for(h, driver, 1.0)
    assert idle[1].ask("robot:robot.modules=()") == "robot:robot.modules=(demo,arm)"
    early = h.connect()  # nobody has been silent for 5 s yet
    assert closed_after_busy(early) == "robot:mcp.error=(busy,too many clients; at most 4)"
    drive_for(h, driver, 4.5)  # idle[0] and idle[2]: 5.5 s of silence; idle[1]: 4.5 s
    with caplog.at_level(logging.WARNING, logger="ramp.layers.server"):
        operator = h.connect()
    assert closed_after_busy(idle[0]).startswith(
        "robot:mcp.error=(busy,closed to make room for another client: no message for 5 s")
    assert "evicted: no message for 5.5 s" in caplog.text
    assert h.world.motors["demo.motor"] == 0.5
    assert operator.ask("robot:robot.stop=()") == ""
    assert h.world.motors["demo.motor"] == 0.0
    assert len(h.sup.server.clients) == 4
    # the next newcomer takes the slot of idle[2], the next silent one
    third = h.connect()
    assert closed_after_busy(idle[2]).startswith("robot:mcp.error=(busy,closed to make room")
    assert third.ask("robot:robot.modules=()") == "robot:robot.modules=(demo,arm)"


def test_a_silent_feeder_of_an_armed_watchdog_keeps_its_slot(h: Harness) -> None:
    """Evicting the feeder would trip the watchdog and stop its motion: it stays."""
    feeder = h.connect()
    assert feeder.ask("robot:watchdog.timeout=(60)") == ""
    assert feeder.ask("demo:motor.vel=(30)") == ""  # armed, for a minute of silence
    talkers = [h.connect() for _ in range(3)]
    for _ in range(60):  # 6 s: the feeder is silent, the others keep talking
        h.advance(0.1)
        for c in talkers:
            assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(demo,arm)"
    newcomer = h.connect()
    assert closed_after_busy(newcomer).startswith("robot:mcp.error=(busy,too many clients")
    assert h.world.motors["demo.motor"] == 0.3
    assert "watchdog.state=(armed)" in talkers[0].ask("robot:robot.get=()")


def test_a_silent_owner_keeps_its_slot_and_a_silent_other_goes(h: Harness) -> None:
    owner = h.connect()
    assert owner.ask("robot:control.acquire=(autonomy)") == ""
    idle = h.connect()
    talkers = [h.connect(), h.connect()]
    for _ in range(60):
        h.advance(0.1)
        for c in talkers:
            assert c.ask("") == ""
    newcomer = h.connect()
    assert closed_after_busy(idle).startswith("robot:mcp.error=(busy,closed to make room")
    assert owner.ask("robot:robot.get=()").count("control.owner=(autonomy)") == 1
    assert newcomer.ask("robot:robot.stop=()") == ""


def test_bytes_without_a_newline_are_not_a_message(h: Harness) -> None:
    """A client trickling a message it never ends has sent no complete message."""
    trickler = h.connect()
    talkers = [h.connect() for _ in range(3)]
    for i in range(60):
        h.advance(0.1)
        trickler.send("robot:robot.get"[i % 15])
        h.pump_io()
        for c in talkers:
            assert c.ask("") == ""
    newcomer = h.connect()
    assert closed_after_busy(trickler).startswith("robot:mcp.error=(busy,closed to make room")
    assert newcomer.ask("") == ""
