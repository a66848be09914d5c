"""A bug in one driver is one bus's fault (SPEC 2.2, issue 19 item 4): a deliberately broken
driver beside working ones, over TCP. Before, the bus manager caught only DeviceError: any
other exception from one driver aborted the loop over the remaining buses on every tick (their
modules stayed `ok` with no fresh readings) and the scheduler logged a traceback a hundred
times a second."""

from __future__ import annotations

import logging
from typing import Any

import pytest

from ramp.clock import VirtualClock
from ramp.config import BusConfig
from ramp.hal.interfaces import Bus
from ramp.hal.simio import SimBus
from ramp.layers.module_distribution import Task
from ramp.runtime import build
from tests.harness import FakeWorld, Harness, config_from, value

# The Base on one healthy bus ("io"), a demo module on a broken one ("bad", first in the
# dict, so its tick runs before io's), and an arm on a third.
YAML = """
server: {host: 127.0.0.1, port: 0, max_clients: 4}
watchdog: {timeout: 0.5}
buses:
  bad: {driver: sim}
  io: {driver: sim}
  io3: {driver: sim}
modules:
  demo: {motor: {bus: bad}, lamp: {bus: bad}}
  base:
    lf_wheel: {bus: io}
    lb_wheel: {bus: io3}
    rf_wheel: {bus: io3}
    rb_wheel: {bus: io3}
    battery: {bus: io}
    l_button: {bus: io}
    r_button: {bus: io3}
    user_led: {bus: io}
    led_high: {bus: io3}
    led_mid: {bus: io3}
    led_low: {bus: io3}
"""


def battery_volts(rail: float) -> float:
    return 2.5 + 0.0681 * rail


class BrokenBus(SimBus):
    """A sim bus whose driver has a bug where `broken` says."""

    broken: set[str] = set()

    def _tick(self, now: float, dt: float) -> None:
        if "tick" in self.broken:
            raise ZeroDivisionError("division by zero in the frame parser")
        super()._tick(now, dt)

    def _motor_changed(self, ch: Any) -> None:
        if "command" in self.broken:
            raise KeyError("no such register")
        super()._motor_changed(ch)


@pytest.fixture
def h() -> Any:
    BrokenBus.broken = set()
    world = FakeWorld()
    world.analog["base.battery"] = battery_volts(20.0)

    def factory(bc: BusConfig) -> Bus:
        cls = BrokenBus if bc.name == "bad" else SimBus
        return cls(bc.name, dict(bc.params), world=world)

    harness = Harness(YAML, world=world, bus_factory=factory)
    harness.sup.settle()
    yield harness
    harness.close()


def tracebacks(caplog: pytest.LogCaptureFixture) -> int:
    return sum(1 for r in caplog.records if r.exc_info is not None)


def test_a_driver_raising_in_its_tick_faults_its_bus_only(
        h: Harness, caplog: pytest.LogCaptureFixture) -> None:
    c = h.connect()
    assert c.ask("demo:motor.vel=(30)base:lf_wheel.vel=(40)") == ""
    BrokenBus.broken = {"tick"}
    with caplog.at_level(logging.DEBUG, logger="ramp"):
        for i in range(50):  # 5 s: the broken bus is retried about five times
            h.advance(0.1)
            h.world.analog["base.battery"] = battery_volts(20.0 - 0.1 * i)
            get = c.ask("robot:robot.get=()base:base.get=()")
            assert "robot:base.state=(ok)" in get
            assert "robot:demo.state=(fault)" in get
    # the other buses kept ticking: the battery reading followed the world
    assert float(value(get, "base:battery.volt")) < 17.0
    assert value(get, "base:lf_wheel.vel") == "40"  # c keeps talking: its base drives on
    assert h.world.motors["base.lf_wheel"] == 0.4
    assert h.world.motors["demo.motor"] == 0.0  # the broken bus's motion stopped
    assert c.ask("demo:motor.vel=(10)").startswith(
        "demo:motor.error=(fault,module demo is fault: bus bad: driver error in tick: "
        "ZeroDivisionError: division by zero in the frame parser)")
    assert tracebacks(caplog) == 1
    assert sum("bus bad fault" in r.getMessage() and r.levelno >= logging.ERROR
               for r in caplog.records) == 1  # the repeats are quiet
    assert h.sup.bus_manager.health["bad"].faults >= 3  # retried like hot plug
    BrokenBus.broken = set()  # fixed (a transient bug): the retry brings it back
    h.advance(1.5)
    assert "robot:demo.state=(ok)" in c.ask("robot:robot.get=()")
    assert c.ask("demo:motor.vel=(10)") == ""


def test_a_driver_raising_on_a_command_faults_its_bus(
        h: Harness, caplog: pytest.LogCaptureFixture) -> None:
    c = h.connect()
    BrokenBus.broken = {"command"}
    with caplog.at_level(logging.ERROR, logger="ramp"):
        assert c.ask("demo:motor.vel=(30)") == ""
        h.advance(0.05)
        assert "robot:demo.state=(fault)" in c.ask("robot:robot.get=()")
        assert c.ask("base:lf_wheel.vel=(20)") == ""  # the rest serve on
        assert h.world.motors["base.lf_wheel"] == 0.2
    assert tracebacks(caplog) == 1
    assert "driver error in a motor command: KeyError" in caplog.text


def test_a_module_task_raising_faults_that_module_only(caplog: pytest.LogCaptureFixture) -> None:
    world = FakeWorld()
    world.analog["base.battery"] = battery_volts(20.0)
    sup = build(config_from(YAML), VirtualClock(),
                lambda bc: SimBus(bc.name, dict(bc.params), world=world),
                host="127.0.0.1", port=0)
    calls = {"n": 0, "broken": True}

    def flaky(now: float, dt: float) -> None:
        calls["n"] += 1
        if calls["broken"]:
            raise IndexError("list index out of range")

    demo = sup.slots["demo"].module
    demo.tasks = lambda: [Task("flaky", 100.0, flaky)]  # type: ignore[method-assign]
    sup.start()
    try:
        sup.settle()
        robot = sup.robot
        with caplog.at_level(logging.ERROR, logger="ramp"):
            demo._vel(30)  # type: ignore[attr-defined]
            sup.scheduler.run_for(0.05)
            assert sup.slots["demo"].state == "fault"
            assert world.motors["demo.motor"] == 0.0  # its motion stopped
            assert sup.slots["base"].state == "ok"
            sup.scheduler.run_for(5.0)
        assert 3 <= calls["n"] <= 7  # retried about once a second, not every tick
        assert sum(1 for r in caplog.records if r.exc_info is not None) == 1
        assert "task flaky raised IndexError: list index out of range" in \
            sup.slots["demo"].reason or sup.slots["demo"].state == "ok"
        calls["broken"] = False
        sup.scheduler.run_for(1.5)
        assert sup.slots["demo"].state == "ok"
        assert robot.watchdog.state == "idle"
    finally:
        sup.shutdown()
