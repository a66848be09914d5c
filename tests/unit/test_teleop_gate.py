"""The motion gate, sans I/O: motion after our own goes behind a check, a stop never waits."""

from __future__ import annotations

from ramp.mcp.messages import Request, Response
from ramp.teleop.gate import MotionGate

DRIVE = [Request("base", "base", "drive", ("50", "0"))]
DRIVE2 = [Request("base", "base", "drive", ("51", "0"))]
CHAIN = [Request("ble", "chain", "vel", ("30",))]
STOP = [Request("base", "base", "stop")]


def watchdog(state: str) -> list[Response]:
    return [Response("robot", "watchdog", "state", (state,))]


def test_the_first_motion_goes_at_once_and_the_next_waits_for_a_check() -> None:
    gate = MotionGate()
    assert gate.offer(DRIVE) == (DRIVE, False)
    assert gate.offer(DRIVE2) == (None, True)
    assert gate.offer(CHAIN) == (None, False)  # merged into what is held
    assert gate.answered(watchdog("armed")) == (DRIVE2 + CHAIN, "")
    assert gate.moving


def test_a_stop_by_someone_else_drops_what_is_held_and_says_why() -> None:
    for state, why in (("idle", "stopped by someone else"), ("tripped", "watchdog tripped")):
        gate = MotionGate()
        gate.offer(DRIVE)
        assert gate.offer(DRIVE2) == (None, True)
        held, reason = gate.answered(watchdog(state))
        assert held is None and why in reason and not gate.moving


def test_a_stop_goes_at_once_and_cancels_what_is_held() -> None:
    gate = MotionGate()
    gate.offer(DRIVE)
    gate.offer(DRIVE2)
    assert gate.offer(STOP) == (STOP, False)
    assert gate.answered(watchdog("armed")) == (None, "")
    assert gate.offer(DRIVE) == (DRIVE, False)  # nothing of ours moves: no check


def test_motion_back_to_rest_needs_no_check_afterwards() -> None:
    gate = MotionGate()
    gate.offer(DRIVE)
    gate.offer([Request("base", "base", "drive", ("0", "0"))])
    gate.answered(watchdog("armed"))
    assert not gate.moving  # a stick at rest: the robot's idle watchdog is ours
    assert gate.offer(DRIVE) == (DRIVE, False)
    assert gate.offer([]) == ([], False)  # heartbeats always go


def test_motion_the_robot_refused_is_not_ours_to_guard() -> None:
    gate = MotionGate()
    gate.offer(DRIVE)  # answered not_owner: the autonomy owns control
    gate.forget({"base"})
    assert gate.offer(DRIVE2) == (DRIVE2, False)  # no check, no false latch
