"""The `phidget` driver's servo channels (SPEC 10's servo kind on Phidget22 RCServo): degrees
mapped onto pulses, speed limit, target then engage, the position the board reports, and a
stop that holds the servo where it is."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import pytest

from ramp.hal.interfaces import ServoChannel
from ramp.hal.phidget import PhidgetBus
from tests.unit.test_phidget_driver import FakeBoard, FakeChannel, on_library_thread


class FakeRCServo(FakeChannel):
    """Phidget22 RCServo: settings only once attached, a target within Min/MaxPosition."""

    def __init__(self, board: FakeBoard) -> None:
        super().__init__(board)
        self.pulse = (0.0, 0.0)
        self.position_range = (-math.inf, math.inf)
        self.ramping = False
        self.velocity_limit = 0.0
        self.target: float | None = None
        self.engaged = False

    def setOnPositionChangeHandler(self, h: Any) -> None:
        self.handlers["sample"] = h

    def getMinPulseWidthLimit(self) -> float:
        self._need_attached()
        return 500.0

    def getMaxPulseWidthLimit(self) -> float:
        self._need_attached()
        return 2500.0

    def setMinPulseWidth(self, us: float) -> None:
        self._need_attached()
        self.pulse = (us, self.pulse[1])

    def setMaxPulseWidth(self, us: float) -> None:
        self._need_attached()
        self.pulse = (self.pulse[0], us)

    def setMinPosition(self, p: float) -> None:
        self.position_range = (p, self.position_range[1])

    def setMaxPosition(self, p: float) -> None:
        self.position_range = (self.position_range[0], p)

    def setSpeedRampingState(self, on: bool) -> None:
        self.ramping = on

    def getMinVelocityLimit(self) -> float:
        return 0.0

    def getMaxVelocityLimit(self) -> float:
        return 1000.0

    def setVelocityLimit(self, v: float) -> None:
        self._need_attached()
        self.velocity_limit = v

    def setTargetPosition(self, p: float) -> None:
        self._need_attached()
        lo, hi = self.position_range
        assert lo <= p <= hi
        self.target = p

    def getEngaged(self) -> bool:
        return self.engaged

    def setEngaged(self, on: bool) -> None:
        assert self.target is not None, "engaging with no target makes the servo jump"
        self.engaged = on


@pytest.fixture
def rig() -> tuple[PhidgetBus, ServoChannel, FakeRCServo]:
    board = FakeBoard()
    api = replace(board.api, RCServo=lambda: FakeRCServo(board))
    bus = PhidgetBus("arm_servos", {"serial": 77}, api=api)
    servo = bus.channel("servo", "arm.elbow",
                        {"channel": 1, "neutral_us": 1500.0, "us_per_deg": 10.0,
                         "reversed": True})
    bus.open(0.0)
    handle = next(c for c in board.created if isinstance(c, FakeRCServo))
    on_library_thread(handle.plug)
    bus.tick(0.01, 0.01)
    return bus, servo, handle


def test_attach_maps_degrees_onto_pulses_and_ramps_speed(rig: Any) -> None:
    bus, servo, h = rig
    assert h.pulse == (500.0, 2500.0) and h.position_range == (-100.0, 100.0)
    assert h.ramping and bus.ready()


def test_a_move_sets_the_speed_limit_then_the_target_then_engages(rig: Any) -> None:
    bus, servo, h = rig
    servo.move(30.0, 45.0)
    bus.tick(0.02, 0.01)
    assert h.velocity_limit == 45.0
    assert h.target == -30.0  # reversed
    assert h.engaged
    on_library_thread(lambda: h.fire("sample", -12.0))
    bus.tick(0.03, 0.01)
    assert servo.read() == 12.0


def test_a_stop_holds_the_servo_where_it_reports_it_is(rig: Any) -> None:
    bus, servo, h = rig
    servo.move(60.0, 30.0)
    bus.tick(0.02, 0.01)
    on_library_thread(lambda: h.fire("sample", -20.0))
    bus.tick(0.03, 0.01)
    bus.stop_motors()
    assert servo.target == 20.0 and h.target == -20.0  # at once, not at the next tick
