"""The `phidget` driver's servo channels (SPEC 10's servo kind on Phidget22 RCServo): degrees
mapped onto pulses, speed limit, target then engage, the position the board reports, and a
stop that holds the servo where it is."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from ramp.hal.interfaces import ServoChannel
from ramp.hal.phidget import PhidgetBus
from tests.fake_phidget22 import FakeRCServo, install
from tests.unit.test_phidget_driver import FakeBoard, on_library_thread


@pytest.fixture
def rig(monkeypatch: pytest.MonkeyPatch) -> tuple[PhidgetBus, ServoChannel, FakeRCServo]:
    install(monkeypatch)  # a fresh fake library (another test may have broken the last one)
    board = FakeBoard()
    made: list[FakeRCServo] = []

    def rcservo() -> FakeRCServo:
        made.append(FakeRCServo())
        return made[-1]

    api = replace(board.api, RCServo=rcservo)
    bus = PhidgetBus("arm_servos", {"serial": 77}, api=api)
    servo = bus.channel("servo", "arm.elbow",
                        {"channel": 1, "neutral_us": 1500.0, "us_per_deg": 10.0,
                         "reversed": True})
    bus.open(0.0)
    handle = made[0]
    on_library_thread(handle.plug)
    bus.tick(0.01, 0.01)
    return bus, servo, handle


def test_attach_maps_degrees_onto_pulses_and_ramps_speed(rig: Any) -> None:
    bus, servo, h = rig
    assert (h.min_pulse, h.max_pulse) == (500.0, 2500.0)
    assert (h.min_pos, h.max_pos) == (-100.0, 100.0)
    assert h.ramping and bus.ready()


def test_a_move_sets_the_speed_limit_then_the_target_then_engages(rig: Any) -> None:
    bus, servo, h = rig
    servo.move(30.0, 45.0)
    bus.tick(0.02, 0.01)
    assert h.velocity_limit == 45.0
    assert [p for p, _ in h.pending] == [-30.0]  # reversed; sent without waiting for USB
    on_library_thread(h.complete)
    bus.tick(0.025, 0.005)
    assert h.target == -30.0 and h.engaged  # engaged once the board holds the target
    on_library_thread(lambda: h.fire("position", -12.0))
    bus.tick(0.03, 0.01)
    assert servo.read() == 12.0


def test_a_stop_holds_the_servo_where_it_reports_it_is(rig: Any) -> None:
    bus, servo, h = rig
    h.async_supported = False
    servo.move(60.0, 30.0)
    bus.tick(0.02, 0.01)
    assert h.target == -60.0 and h.engaged
    on_library_thread(lambda: h.fire("position", -20.0))
    bus.tick(0.03, 0.01)
    bus.stop_motors()
    assert servo.target == 20.0 and h.target == -20.0  # at once, not at the next tick
