"""Idle ticks on the whole supervisor (`scheduler.idle_rate_hz`): MARTE at rest ticks at 20 Hz,
a motion request brings every base tick back from the next slot, a stop lets it rest again;
what is still on its way to a wire, a servo still travelling or a bus still opening keeps the
base rate, and so does a robot with an interlock rule that stops or latches (Scout's bumper)."""

from __future__ import annotations

import math

import pytest

from ramp.hal.interfaces import SERVO_AT_REST_DEG, MotorChannel, ServoChannel
from ramp.runtime.build import IDLE_RATE_HZ
from tests.harness import MARTE_YAML, SCOUT_YAML, SimHarness, config_from, value

IDLE_YAML = MARTE_YAML.replace("scheduler: {rate_hz: 100}",
                               "scheduler: {rate_hz: 100, idle_rate_hz: 20}")


@pytest.fixture
def h() -> SimHarness:
    assert IDLE_YAML != MARTE_YAML
    harness = SimHarness(IDLE_YAML)
    yield harness
    harness.close()


def ticks_in(h: SimHarness, seconds: float) -> int:
    before = h.sup.scheduler.stats.ticks
    h.advance(seconds)
    return h.sup.scheduler.stats.ticks - before


def test_at_rest_it_ticks_at_the_idle_rate_and_from_a_motion_request_at_the_base_rate(
        h: SimHarness) -> None:
    c = h.connect()
    assert ticks_in(h, 1.0) == 20
    assert c.ask("base:base.drive=(40,0)") == ""
    assert h.sup.robot.watchdog.state == "armed"
    beat = h.sup.scheduler._next
    assert beat is not None and beat - h.clock.now() <= 0.01 + 1e-9  # the next base slot
    for _ in range(5):
        assert ticks_in(h, 0.1) == 10
        assert c.ask("robot:robot.get=()").startswith("robot:")  # its heartbeat
    assert c.ask("base:base.stop=()") == ""
    h.advance(0.2)  # the stop's zeros go out, the robot rests
    assert ticks_in(h, 1.0) == 20


def test_a_silent_commander_still_trips_the_watchdog_on_time(h: SimHarness) -> None:
    c = h.connect()
    h.advance(0.5)
    assert c.ask("robot:watchdog.timeout=(0.3)ble:chain.vel=(50)") == ""
    h.advance(0.29)
    assert h.sup.robot.watchdog.state == "armed"
    h.advance(0.03)
    assert h.sup.robot.watchdog.state == "tripped"
    h.advance(0.1)
    emu = h.backplane.sabertooth["ble_motors"].emulator
    assert emu.duty(130, 1) == 0.0 and emu.duty(130, 2) == 0.0
    assert ticks_in(h, 1.0) == 20  # tripped and stopped: at rest


def test_a_command_still_waiting_for_the_wire_keeps_the_base_rate(h: SimHarness) -> None:
    """A Sabertooth at 9600 baud paces its packets: while some wait, the bus is not at rest."""
    bus = h.sup.buses["base_motors"]
    assert bus.at_rest() and not bus.output_queued()
    bus._pending[next(iter(bus._channels))] = None  # as a burst over the budget leaves it
    assert not bus.at_rest()
    assert not h.sup.at_rest()
    bus._pending.clear()
    assert h.sup.at_rest()


def test_a_motor_turned_by_a_module_task_alone_is_not_rest(h: SimHarness) -> None:
    """Motion that no client commanded (a module's own controller) still counts."""
    wheel = next(m for m in h.sup.buses["base_motors"].motors)
    wheel.duty = 0.2
    assert not h.sup.at_rest()
    wheel.duty = 0.0
    assert h.sup.at_rest()


class _Bus:
    """The parts of a bus `Bus.at_rest` reads, with no driver behind them."""

    def __init__(self) -> None:
        self.motors: list[MotorChannel] = []
        self.servos: list[ServoChannel] = []
        self.queued = False

    def output_queued(self) -> bool:
        return self.queued


def test_a_servo_is_at_rest_where_it_was_sent_and_not_while_it_travels() -> None:
    from ramp.hal.interfaces import Bus

    bus = _Bus()
    sv = ServoChannel(None, "arm.shoulder")  # type: ignore[arg-type]
    bus.servos.append(sv)
    assert Bus.at_rest(bus)  # type: ignore[arg-type]  # no target
    sv.target, sv.position = 90.0, math.nan
    assert not Bus.at_rest(bus)  # type: ignore[arg-type]  # not reported yet
    sv.position = 40.0
    assert not Bus.at_rest(bus)  # type: ignore[arg-type]
    sv.position = 90.0 - SERVO_AT_REST_DEG / 2
    assert Bus.at_rest(bus)  # type: ignore[arg-type]
    bus.queued = True
    assert not Bus.at_rest(bus)  # type: ignore[arg-type]


def test_the_wall_clock_default_is_the_idle_rate_and_a_virtual_clock_ticks_every_period() -> None:
    from ramp.clock import MonotonicClock, VirtualClock
    from ramp.runtime.build import build

    config = config_from(MARTE_YAML.replace("port: 5577", "port: 0"))
    assert config.idle_rate_hz is None
    for clock, stride in ((MonotonicClock(), round(100 / IDLE_RATE_HZ)), (VirtualClock(), 1)):
        sup = build(config, clock, host="127.0.0.1", port=0)
        assert sup.scheduler.idle_stride == stride
    every = config_from(MARTE_YAML.replace("port: 5577", "port: 0").replace(
        "scheduler: {rate_hz: 100}", "scheduler: {rate_hz: 100, idle_rate_hz: 100}"))
    assert build(every, MonotonicClock(), host="127.0.0.1", port=0).scheduler.idle_stride == 1


SCOUT_IDLE_YAML = SCOUT_YAML.replace("scheduler: {rate_hz: 100}",
                                     "scheduler: {rate_hz: 100, idle_rate_hz: 20}")


@pytest.mark.parametrize("press_s", [0.035, 0.045])
def test_a_robot_with_a_latching_rule_keeps_the_base_rate_so_a_short_bump_latches(
        press_s: float) -> None:
    """Scout's `bumper` rule stops and latches on a debounced input (20 ms at 100 Hz): at
    20 Hz a press shorter than two idle ticks would fall between samples and never latch.
    Such a robot ticks at the base rate at rest too."""
    assert SCOUT_IDLE_YAML != SCOUT_YAML
    h = SimHarness(SCOUT_IDLE_YAML, marte=False)
    try:
        assert h.sup.scheduler.idle_stride == 1
        c = h.connect()
        h.advance(0.513)
        assert h.sup.at_rest()
        assert c.ask("sim:input.set=(base,bumper_left,1)") == ""
        h.advance(press_s)
        assert c.ask("sim:input.clear=(base,bumper_left)") == ""
        h.advance(0.3)
        assert "bumper" in value(c.ask("robot:robot.get=()"), "robot:interlock.active")
    finally:
        h.close()
