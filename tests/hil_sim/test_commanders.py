"""Every commander feeds for itself (SPEC 2.2, issue 19 items 1 and 2), over TCP against the
simulated MARTE, watched on the emulated wire (what the Sabertooth emulators receive)."""

from __future__ import annotations

import pytest

from tests.harness import SimHarness, value
from tests.harness import TestClient as Client


@pytest.fixture
def h() -> SimHarness:
    harness = SimHarness()
    yield harness
    harness.close()


def base_wire(h: SimHarness) -> list[float]:
    """The four wheel duties the base's Sabertooths are applying now."""
    emu = h.backplane.sabertooth["base_motors"].emulator
    return [emu.duty(a, m) for a in (128, 129) for m in (1, 2)]


def chain_wire(h: SimHarness) -> list[float]:
    emu = h.backplane.sabertooth["ble_motors"].emulator
    return [emu.duty(130, 1), emu.duty(130, 2)]


def poll_for(h: SimHarness, talkers: list[Client], seconds: float, step: float = 0.1,
             ask: str = "base:base.get=()") -> None:
    """`seconds` pass; each talker sends `ask` every `step`."""
    for _ in range(round(seconds / step)):
        h.advance(step)
        for c in talkers:
            c.ask(ask)


def test_a_polling_client_never_keeps_a_silent_commanders_motors_running(h: SimHarness) -> None:
    """The issue's reproduction: A drives, B commands the chain to 0 and then only polls; A
    goes silent. Before: B became "the feeder" and the base drove at 50 % for as long as B
    polled. Now A's silence stops everything after A's timeout (1 s)."""
    a, b = h.connect(), h.connect()
    assert a.ask("base:base.drive=(50,0)") == ""
    assert b.ask("ble:chain.vel=(0)") == ""
    poll_for(h, [a, b], 0.5)  # both talking: driving
    assert all(d != 0 for d in base_wire(h))
    poll_for(h, [b], 1.3)  # A silent, B polls
    assert base_wire(h) == [0.0] * 4
    get = b.ask("robot:robot.get=()")
    assert value(get, "robot:watchdog.state") == "tripped"
    assert "base:lf_wheel.vel=(0)" in b.ask("base:base.get=()")
    poll_for(h, [b], 2.0)
    assert base_wire(h) == [0.0] * 4  # and it stays stopped


def test_a_commander_that_closes_its_socket_stops_everything_at_once(h: SimHarness) -> None:
    a, b = h.connect(), h.connect()
    assert a.ask("base:base.drive=(50,0)") == ""
    assert b.ask("ble:chain.vel=(0)") == ""
    poll_for(h, [a, b], 0.3)
    a.close()
    h.advance(0.05)
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.state") == "tripped"
    h.advance(0.05)
    assert base_wire(h) == [0.0] * 4


def test_every_commander_of_a_moving_module_must_talk(h: SimHarness) -> None:
    """A drives the base, B runs the chain: both must keep talking; B's silence stops A's
    base too, and A's messages never count for B."""
    a, b = h.connect(), h.connect()
    assert a.ask("base:base.drive=(40,0)") == ""
    assert b.ask("ble:chain.vel=(60)") == ""
    poll_for(h, [a, b], 0.5)
    assert value(a.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "2"
    assert all(d != 0 for d in base_wire(h)) and all(d != 0 for d in chain_wire(h))
    poll_for(h, [a], 1.2)  # B silent
    assert base_wire(h) == [0.0] * 4 and chain_wire(h) == [0.0, 0.0]
    assert value(a.ask("robot:robot.get=()"), "robot:watchdog.state") == "tripped"


def test_a_second_clients_unrelated_motion_does_not_feed_the_first(h: SimHarness) -> None:
    a, b = h.connect(), h.connect()
    assert a.ask("base:base.drive=(40,0)") == ""
    for _ in range(12):  # B keeps sending motion to another module; A is silent
        h.advance(0.1)
        assert b.ask("ble:chain.vel=(30)") == ""
    assert base_wire(h) == [0.0] * 4


def test_the_last_motion_request_makes_its_sender_the_commander(h: SimHarness) -> None:
    """B takes over A's module by commanding it: from then on B must talk, not A."""
    a, b = h.connect(), h.connect()
    assert a.ask("base:base.drive=(40,0)") == ""
    h.advance(0.2)
    assert b.ask("base:base.drive=(20,0)") == ""
    poll_for(h, [b], 2.0, ask="")  # A silent: no longer its motion
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.state") == "armed"
    assert all(d != 0 for d in base_wire(h))


def test_a_commander_of_a_module_at_rest_need_not_talk(h: SimHarness) -> None:
    a, b = h.connect(), h.connect()
    assert b.ask("ble:chain.vel=(30)") == ""
    assert b.ask("ble:chain.vel=(0)") == ""
    assert a.ask("base:base.drive=(40,0)") == ""
    poll_for(h, [a], 2.0, ask="")  # B silent, but nothing of its moves
    assert value(a.ask("robot:robot.get=()"), "robot:watchdog.state") == "armed"
    b.close()  # nor does its disconnect stop A
    h.advance(0.1)
    assert value(a.ask("robot:robot.get=()"), "robot:watchdog.state") == "armed"
    assert all(d != 0 for d in base_wire(h))


def test_each_client_sets_its_own_timeout_and_it_goes_with_it(h: SimHarness) -> None:
    """Before: one global timeout that any client could change for everyone, and it stayed
    after that client left."""
    a, b, c = h.connect(), h.connect(), h.connect()
    assert a.ask("robot:watchdog.timeout=(0.3)") == ""
    assert b.ask("robot:watchdog.timeout=(5)") == ""
    assert value(a.ask("robot:robot.get=()"), "robot:watchdog.timeout") == "0.3"
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.timeout") == "5.0"
    assert value(c.ask("robot:robot.get=()"), "robot:watchdog.timeout") == "1.0"
    # B's long timeout never stretches A's: A silent 0.4 s trips.
    assert a.ask("base:base.drive=(40,0)") == ""
    assert b.ask("ble:chain.vel=(30)") == ""
    poll_for(h, [b], 0.4, ask="")
    assert value(c.ask("robot:robot.get=()"), "robot:watchdog.state") == "tripped"
    # B's 5 s holds while B is silent 3 s.
    assert b.ask("ble:chain.vel=(30)") == ""
    poll_for(h, [c], 3.0)
    assert value(c.ask("robot:robot.get=()"), "robot:watchdog.state") == "armed"
    assert all(d != 0 for d in chain_wire(h))
    assert b.ask("ble:ble.stop=()") == ""
    # Gone with its connection: the next client starts from the default.
    b.close()
    d = h.connect()
    assert value(d.ask("robot:robot.get=()"), "robot:watchdog.timeout") == "1.0"
    assert value(c.ask("robot:robot.get=()"), "robot:watchdog.timeout") == "1.0"


def test_commanders_row_counts_the_clients_that_must_talk(h: SimHarness) -> None:
    a, b = h.connect(), h.connect()
    assert "robot:watchdog.property=(commanders,int)" in a.ask("robot:robot.describe=()")
    assert value(a.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "0"
    assert a.ask("base:base.drive=(40,0)") == ""
    assert b.ask("ble:chain.vel=(0)") == ""  # commands a module at rest: need not talk
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "1"
    assert b.ask("ble:chain.vel=(20)") == ""
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "2"
    # A commands the BLE's lift now: commanders are per device (SPEC 2.2, issue 33), so B
    # still commands the chain it set moving and must keep talking.
    assert a.ask("ble:lift.vel=(20)") == ""
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "2"
    # A takes the chain too: now B commands nothing and need not talk.
    assert a.ask("ble:chain.vel=(30)") == ""
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "1"
    assert b.ask("robot:robot.stop=()") == ""
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "0"


def closed_after(c: Client) -> str:
    """The farewell line of a client the server closes."""
    line = c.line()
    with pytest.raises(ConnectionError):
        c.line()
    return line


def test_every_commander_of_a_moving_module_keeps_its_slot() -> None:
    """Always room for a stop (SPEC 2.2) without stopping the robot: with every slot taken,
    a silent commander of a moving module is never evicted (before, only the last
    commander, "the feeder", was protected, and evicting the other stopped everything); a
    silent client commanding nothing that moves is."""
    from tests.harness import Harness

    h = Harness()  # max_clients 4; modules demo and arm
    try:
        a, b, idle = h.connect(), h.connect(), h.connect()
        for c, module in ((a, "demo"), (b, "arm")):
            assert c.ask("robot:watchdog.timeout=(60)") == ""
            assert c.ask(f"{module}:motor.vel=(30)") == ""
        talker = h.connect()
        for _ in range(60):  # 6 s: a, b and idle silent
            h.advance(0.1)
            assert talker.ask("") == ""
        newcomer = h.connect()  # evicts idle, the only one it may
        assert closed_after(idle).startswith("robot:mcp.error=(busy,closed to make room")
        assert h.world.motors["demo.motor"] == 0.3 and h.world.motors["arm.motor"] == 0.3
        for _ in range(60):
            h.advance(0.1)
            assert talker.ask("") == "" and newcomer.ask("") == ""
        late = h.connect()  # a and b are silent, but command moving modules: busy
        assert closed_after(late).startswith("robot:mcp.error=(busy,too many clients")
        assert h.world.motors["demo.motor"] == 0.3 and h.world.motors["arm.motor"] == 0.3
        assert "robot:watchdog.state=(armed)" in talker.ask("robot:robot.get=()")
    finally:
        h.close()


# -- commanders per device, not per module (issue 33 item 2) ---------------------------------

def test_a_second_client_touching_one_wheel_never_takes_over_the_other_three(
        h: SimHarness) -> None:
    """The issue's reproduction: A drives, B sets one wheel to 30 and keeps heartbeating; A
    disconnects. Before: B had replaced A as the base's commander and three wheels kept A's
    60 %. Now A still commands the three wheels B did not touch: its loss stops everything."""
    a, b = h.connect(), h.connect()
    assert a.ask("base:base.drive=(60,0)") == ""
    assert b.ask("base:lf_wheel.vel=(30)") == ""
    poll_for(h, [a, b], 0.3, ask="")
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "2"
    a.close()
    poll_for(h, [b], 0.2, ask="")
    assert base_wire(h) == [0.0] * 4
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.state") == "tripped"


def test_a_zero_speed_request_never_makes_its_sender_the_commander(h: SimHarness) -> None:
    """The issue's second reproduction: B's `lf_wheel.vel=(0)` with a 60 s timeout kept A's
    three wheels at 60 % for B's 60 s after A vanished. A zero speed is a stop: A stays the
    commander, and A's silence trips the watchdog after A's own 1 s."""
    a, b = h.connect(), h.connect()
    assert b.ask("robot:watchdog.timeout=(60)") == ""
    assert a.ask("base:base.drive=(60,0)") == ""
    assert b.ask("base:lf_wheel.vel=(0)") == ""
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "1"
    poll_for(h, [b], 0.6, ask="")
    assert base_wire(h)[1:] != [0.0] * 3  # A's three wheels still run on A's 1 s
    poll_for(h, [b], 0.6, ask="")
    assert base_wire(h) == [0.0] * 4
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.state") == "tripped"


def test_a_zero_speed_request_with_a_disconnect_trips_too(h: SimHarness) -> None:
    a, b = h.connect(), h.connect()
    assert a.ask("base:base.drive=(60,0)") == ""
    assert b.ask("base:lf_wheel.vel=(0)") == ""
    a.close()
    poll_for(h, [b], 0.1, ask="")
    assert base_wire(h) == [0.0] * 4


def test_a_refused_motion_request_commands_nothing(h: SimHarness) -> None:
    """A request armed before the module's code runs, then refused by it (a latched lift),
    leaves the watchdog as it was: its sender need not talk."""
    a, b = h.connect(), h.connect()
    h.sup.slots["ble"].module.lift.latch.trip("lift stalled: test")
    assert a.ask("base:base.drive=(40,0)") == ""
    assert b.ask("ble:lift.vel=(50)").startswith("ble:lift.error=(fault,")
    assert value(b.ask("robot:robot.get=()"), "robot:watchdog.commanders") == "1"
    poll_for(h, [a], 1.5, ask="")  # B silent: nothing of its moves
    assert value(a.ask("robot:robot.get=()"), "robot:watchdog.state") == "armed"
    assert all(d != 0 for d in base_wire(h))


@pytest.mark.parametrize("method", ["is_moving", "stop"])
def test_a_module_whose_code_raises_is_stopped_on_the_wire(method: str) -> None:
    """Plugin code on the safety path (SPEC 2.2): a module whose `is_moving` or `stop`
    raises goes to `fault` and its motors are zeroed by the bus layer, and the client that
    drove it stays the commander, so its loss trips the watchdog."""
    from tests.harness import Harness

    h = Harness()
    try:
        driver = h.connect()
        assert driver.ask("demo:motor.vel=(50)") == ""
        h.advance(0.05)
        assert h.world.motors["demo.motor"] != 0.0
        module = h.sup.slots["demo"].module

        def broken(*args: object) -> bool:
            raise RuntimeError(f"{method} is broken")

        setattr(module, method, broken)
        if method == "stop":
            assert driver.ask("robot:robot.stop=()") == ""
        else:
            assert driver.ask("arm:motor.vel=(10)") == ""  # asks every module if it moves
        h.advance(0.05)
        assert h.sup.slots["demo"].state == "fault"
        assert h.world.motors["demo.motor"] == 0.0
        assert h.sup.slots["arm"].state == "ok"
    finally:
        h.close()
