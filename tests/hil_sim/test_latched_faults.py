"""Latched faults are acknowledged, never cleared by a stop (SPEC 2.2, issue 19 item 3): the lift
jammed through the `sim` module, over TCP, watched on the emulated wire."""

from __future__ import annotations

import pytest

from tests.harness import SimHarness, value
from tests.harness import TestClient as Client


@pytest.fixture
def h() -> SimHarness:
    harness = SimHarness()
    yield harness
    harness.close()


def lift_wire(h: SimHarness) -> float:
    """The duty the lift's Sabertooth (address 131, motor 1) applies now."""
    return float(h.backplane.sabertooth["ble_motors"].emulator.duty(131, 1))


def fed(h: SimHarness, c: Client, seconds: float) -> None:
    for _ in range(round(seconds / 0.1)):
        h.advance(0.1)
        assert c.ask("") == ""


def stalled(h: SimHarness, c: Client) -> str:
    return value(c.ask("ble:ble.get=()"), "ble:lift.stalled")


def jam_and_latch(h: SimHarness, c: Client) -> None:
    assert c.ask("sim:lift.jam=(1)") == ""
    assert c.ask("ble:lift.extend=()") == ""
    fed(h, c, 2.0)
    assert stalled(h, c) == "1"
    assert lift_wire(h) == 0.0


def refused(c: Client) -> None:
    """Every motion request of the lift answers fault; the chain still runs."""
    for req in ("ble:lift.vel=(50)", "ble:lift.extend=()", "ble:lift.retract=()",
                "ble:lift.pos=(0.5)"):
        answer = c.ask(req)
        assert answer.startswith("ble:lift.error=(fault,lift stalled: "), answer
        assert answer.endswith("acknowledge it with ble:lift.reset)")


def test_the_latch_survives_every_stop_trip_takeover_and_release(h: SimHarness) -> None:
    op, auto = h.connect(), h.connect()
    jam_and_latch(h, op)
    assert op.ask("sim:lift.jam=(0)") == ""  # the rock is gone; nobody acknowledged yet
    steps = [
        (op, "ble:ble.stop=()"),           # the autonomy's and the dead-man's routine stop
        (op, "robot:robot.stop=()"),
        (auto, "robot:control.acquire=(autonomy)"),   # a takeover
        (auto, "robot:control.release=()"),
        (op, "robot:control.acquire=(operator)"),
        (op, "robot:control.release=()"),
    ]
    for c, req in steps:
        assert c.ask(req) == ""
        h.advance(0.1)
        assert stalled(h, op) == "1", req
        refused(c)  # (the owner's requests, while someone owns control)
    # a watchdog trip: the chain's commander goes silent
    assert auto.ask("ble:chain.vel=(40)") == ""
    h.advance(1.2)
    assert value(op.ask("robot:robot.get=()"), "robot:watchdog.state") == "tripped"
    assert stalled(h, op) == "1"
    refused(op)
    # the bus going away and coming back (the module re-attaches from rest)
    assert op.ask("sim:bus.unplug=(ble_motors)") == ""
    h.advance(0.2)
    assert op.ask("sim:bus.plug=(ble_motors)") == ""
    h.advance(2.5)
    assert "robot:ble.state=(ok)" in op.ask("robot:robot.get=()")
    assert stalled(h, op) == "1"
    refused(op)
    assert lift_wire(h) == 0.0  # never moved before the reset
    # the acknowledgement
    assert op.ask("ble:lift.reset=()") == ""
    assert stalled(h, op) == "0"
    assert op.ask("ble:lift.vel=(60)") == ""
    fed(h, op, 1.0)
    assert lift_wire(h) > 0.0 and h.world.lift_pos > 0.02


def test_the_chain_keeps_working_while_the_lift_is_latched(h: SimHarness) -> None:
    c = h.connect()
    jam_and_latch(h, c)
    assert c.ask("ble:chain.vel=(50)") == ""
    fed(h, c, 0.3)
    assert value(c.ask("ble:ble.get=()"), "ble:chain.vel") == "50"


def test_reset_is_kind_state_owner_only_and_described(h: SimHarness) -> None:
    owner, other = h.connect(), h.connect()
    d = other.ask("ble:ble.describe=()")
    assert "ble:lift.function=(reset)" in d and "ble:lift.kind=(reset,state)" in d
    assert "ble:lift.property=(stalled,int)" in d
    jam_and_latch(h, owner)
    assert owner.ask("robot:control.acquire=(operator)") == ""
    assert other.ask("ble:lift.reset=()").startswith("ble:lift.error=(not_owner,")
    assert stalled(h, other) == "1"
    assert owner.ask("ble:lift.reset=()") == ""
    assert stalled(h, other) == "0"


def test_a_reset_while_still_jammed_latches_again(h: SimHarness) -> None:
    c = h.connect()
    jam_and_latch(h, c)
    assert c.ask("ble:lift.reset=()") == ""
    assert c.ask("ble:lift.vel=(100)") == ""
    fed(h, c, 2.0)
    assert stalled(h, c) == "1"
    assert lift_wire(h) == 0.0
    assert h.world.lift_pos == pytest.approx(0.0, abs=1e-6)
