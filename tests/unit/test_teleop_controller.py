"""The console's safety gate on a virtual clock: what goes out, when, and what never does."""

from __future__ import annotations

from ramp.clock import VirtualClock
from ramp.mcp.messages import Request
from ramp.mcp.protocol import format_requests
from ramp.teleop.controller import Controller
from ramp.teleop.mapping import IDLE, Intent, Output

DRIVE = "base:base.drive"
CHAIN = "ble:chain.vel"
TICK = 0.05


def driving(speed: int = 50, chain: int = 0, *, source: str = "gamepad",
            presses: frozenset[tuple[str, tuple[str, ...]]] = frozenset()) -> Intent:
    return Intent(True, source, {
        DRIVE: Output((str(speed), "0.0"), speed == 0),
        CHAIN: Output((str(chain),), chain == 0),
    }, presses)


HELD_AT_REST = driving(0)


def text(messages: list[list[Request]]) -> list[str]:
    return [format_requests(m).decode().rstrip("\n") for m in messages]


class Rig:
    """A controller with one live page, stepped in 50 ms ticks like the console's loop."""

    def __init__(self) -> None:
        self.clock = VirtualClock()
        self.c = Controller()
        self.c.set_link(True, 0.0)
        self.c.open_page("p", 0.0)
        self.focused = True
        self.intent = IDLE

    def send(self, intent: Intent, *, page: str = "p", focused: bool = True) -> list[str]:
        self.intent, self.focused = intent, focused
        self.c.page_input(page, self.clock.now(), focused=focused, intent=intent)
        return text(self.c.tick(self.clock.now()))

    def run(self, seconds: float, *, page_alive: bool = True) -> list[str]:
        """Ticks for `seconds`; a live page re-sends its input each tick, like the real one."""
        out: list[str] = []
        for _ in range(round(seconds / TICK)):
            self.clock.advance(TICK)
            if page_alive:
                self.c.page_input("p", self.clock.now(), focused=self.focused, intent=self.intent)
            out += text(self.c.tick(self.clock.now()))
        return out


def test_holding_the_dead_man_at_rest_sends_nothing() -> None:
    rig = Rig()
    assert rig.send(HELD_AT_REST) == []
    assert rig.run(2.0) == []


def test_motion_is_sent_on_change_then_kept_alive_by_heartbeats() -> None:
    rig = Rig()
    assert rig.send(driving(50)) == ["base:base.drive=(50,0.0)"]
    beats = rig.run(1.0)
    assert beats and set(beats) == {""}
    assert 8 <= len(beats) <= 11  # every 0.1 s
    assert rig.send(driving(60, chain=80)) == ["base:base.drive=(60,0.0)ble:chain.vel=(80)"]
    assert rig.send(driving(60, chain=0)) == ["ble:chain.vel=(0)"]


def test_release_sends_one_stop_for_what_moved_then_silence() -> None:
    rig = Rig()
    rig.send(driving(50, chain=30))
    rig.run(0.3)
    assert rig.send(IDLE) == ["base:base.stop=()ble:ble.stop=()"]
    assert rig.run(3.0) == []  # no stream of zeros, no heartbeats


def test_release_without_motion_sends_nothing() -> None:
    rig = Rig()
    rig.send(HELD_AT_REST)
    assert rig.send(IDLE) == []


def test_a_stalled_page_stops_its_motion_once_after_0_3_s() -> None:
    rig = Rig()
    rig.send(driving(50))
    out = rig.run(0.25, page_alive=False)
    assert set(out) == {""}  # still fresh: heartbeats
    out = rig.run(0.1, page_alive=False)
    assert out == ["base:base.stop=()"]
    assert rig.run(3.0, page_alive=False) == []
    # The page comes back with the dead-man still held: nothing until it is released.
    assert rig.send(driving(50)) == []
    assert rig.c.page_view("p", rig.clock.now())["latched"] is True
    assert rig.run(0.5) == []
    rig.send(IDLE)
    assert rig.send(driving(50)) == ["base:base.drive=(50,0.0)"]


def test_focus_lost_for_longer_than_0_3_s_stops_and_a_short_blur_does_not() -> None:
    rig = Rig()
    rig.send(driving(50))
    rig.send(driving(50), focused=False)
    assert set(rig.run(0.25)) == {""}
    rig.send(driving(50), focused=True)
    assert set(rig.run(0.5)) == {""}
    rig.send(driving(50), focused=False)
    out = rig.run(0.4)
    assert "base:base.stop=()" in out and out[-1] == "base:base.stop=()"
    assert out.count("base:base.stop=()") == 1
    assert rig.run(1.0) == []


def test_a_closed_page_stops_at_the_next_tick() -> None:
    rig = Rig()
    rig.send(driving(50, chain=20))
    rig.c.close_page("p", rig.clock.now())
    assert text(rig.c.tick(rig.clock.now())) == ["base:base.stop=()ble:ble.stop=()"]
    assert rig.run(1.0, page_alive=False) == []
    assert "p" not in rig.c.pages


def test_stop_latches_a_held_dead_man_until_released() -> None:
    rig = Rig()
    rig.send(driving(50))
    rig.c.interrupted(rig.clock.now(), "STOP pressed")
    assert rig.run(1.0) == []  # stick still forward, dead-man still held
    view = rig.c.page_view("p", rig.clock.now())
    assert view["latched"] and not view["engaged"] and view["note"] == "STOP pressed"
    rig.send(IDLE)
    assert rig.send(driving(50)) == ["base:base.drive=(50,0.0)"]


def test_a_lost_link_latches_and_nothing_resumes_on_reconnect() -> None:
    rig = Rig()
    rig.send(driving(50))
    rig.c.set_link(False, rig.clock.now())
    assert rig.run(0.5) == []
    rig.c.set_link(True, rig.clock.now())
    assert rig.run(1.0) == []
    rig.send(IDLE)
    assert rig.send(driving(50)) == ["base:base.drive=(50,0.0)"]


def test_no_engagement_while_the_link_is_down() -> None:
    rig = Rig()
    rig.c.set_link(False, 0.0)
    assert rig.send(driving(50)) == []
    assert rig.c.page_view("p", 0.0)["note"] == "robot link down"


def test_a_typed_motion_is_kept_alive_while_the_page_lives_and_stopped_when_it_dies() -> None:
    rig = Rig()
    rig.send(IDLE)
    rig.c.commanded("p", ["base"], rig.clock.now())
    assert set(rig.run(2.0)) == {""}
    assert rig.c.page_view("p", rig.clock.now())["outstanding"] == ["base"]
    assert rig.run(0.5, page_alive=False)[-1] == "base:base.stop=()"
    assert rig.run(1.0, page_alive=False) == []


def test_refused_motion_is_not_stopped_later() -> None:
    rig = Rig()
    rig.send(driving(50))
    rig.c.forget(["base"])  # the robot answered not_owner
    assert rig.send(IDLE) == []


def test_a_press_fires_once_per_press_while_engaged() -> None:
    rig = Rig()
    extend = frozenset({("ble:lift.extend", ())})
    assert rig.send(driving(0, presses=extend)) == ["ble:lift.extend=()"]
    assert rig.send(driving(0, presses=extend)) == []
    assert rig.send(driving(0)) == []
    assert rig.send(driving(0, presses=extend)) == ["ble:lift.extend=()"]
    assert rig.send(IDLE) == ["ble:ble.stop=()"]


def test_switching_from_pad_to_keys_ends_the_pad_engagement_first() -> None:
    rig = Rig()
    rig.send(driving(50, chain=40))
    out = rig.send(Intent(True, "keyboard", {DRIVE: Output(("50", "180.0"), False)}))
    assert out == ["base:base.stop=()ble:ble.stop=()", "base:base.drive=(50,180.0)"]


def test_only_one_page_drives_at_a_time() -> None:
    rig = Rig()
    rig.c.open_page("q", 0.0)
    rig.send(driving(50))
    rig.c.page_input("q", rig.clock.now(), focused=True, intent=driving(-50))
    assert text(rig.c.tick(rig.clock.now())) == []
    assert rig.c.page_view("q", rig.clock.now())["note"] == "another console page is driving"
    assert rig.send(IDLE) == ["base:base.stop=()"]
    rig.c.page_input("q", rig.clock.now(), focused=True, intent=driving(-50))
    assert text(rig.c.tick(rig.clock.now())) == ["base:base.drive=(-50,0.0)"]


def test_halt_stops_and_latches() -> None:
    rig = Rig()
    rig.send(driving(50))
    assert text(rig.c.halt(rig.clock.now(), "profile switched")) == ["base:base.stop=()"]
    assert rig.run(0.5) == []


def test_stop_for_a_module_comes_from_the_hook() -> None:
    c = Controller(stop_for=lambda m: Request("robot", "robot", "stop"))
    c.set_link(True, 0.0)
    c.open_page("p", 0.0)
    c.page_input("p", 0.0, focused=True, intent=driving(50))
    c.tick(0.0)
    c.page_input("p", 0.05, focused=True, intent=IDLE)
    assert text(c.tick(0.05)) == ["robot:robot.stop=()"]
