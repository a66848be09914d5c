"""The runtime's observer points (README, "Observer points"): what the flight recorder is
wired to. Each point is seen with the supervisor's time; a point nobody observes keeps its
hook at None."""

from __future__ import annotations

import socket
from typing import Any

import pytest

from ramp.clock import VirtualClock
from ramp.hal.simio import SimBus
from ramp.layers.robot_distribution import Client
from ramp.mcp.protocol import TooLong
from ramp.runtime import Observer, Supervisor, build
from tests import harness
from tests.harness import DEMO_YAML, FakeWorld, config_from


class Recording(Observer):
    def __init__(self) -> None:
        self.seen: list[tuple[Any, ...]] = []
        self.ticks = 0
        self.rows: list[Any] = []

    def started(self, supervisor: Supervisor) -> None:
        self.seen.append(("started",))
        supervisor.scheduler.add_task("sample", 10, lambda now, dt: self.rows.append(
            (now, supervisor.health_rows(), supervisor.module_rows("demo"))))

    def stopping(self, supervisor: Supervisor) -> None:
        self.seen.append(("stopping",))

    def message_in(self, t: float, client: Client, message: bytes | TooLong) -> None:
        self.seen.append(("in", client.peer, message))

    def message_out(self, t: float, client: Client, line: bytes) -> None:
        self.seen.append(("out", client.peer, line))

    def command(self, t: float, bus: str, channel: str, value: float) -> None:
        self.seen.append(("command", bus, channel, value))

    def module_state(self, t: float, module: str, state: str, reason: str) -> None:
        self.seen.append(("module", module, state))

    def watchdog(self, t: float, state: str, why: str) -> None:
        self.seen.append(("watchdog", state, why))

    def control(self, t: float, owner: str, peer: str) -> None:
        self.seen.append(("control", owner))

    def bus_fault(self, t: float, bus: str, reason: str) -> None:
        self.seen.append(("bus_fault", bus, reason))

    def tick(self, t: float, late_s: float) -> None:
        self.ticks += 1


class Harness:
    def __init__(self, observer: Observer | None, host: str = "127.0.0.1") -> None:
        self.clock = VirtualClock()
        self.world = FakeWorld()
        self.sup = build(config_from(DEMO_YAML), self.clock,
                         lambda bc: SimBus(bc.name, dict(bc.params), world=self.world),
                         host=host, port=0, observer=observer)
        self.sup.start()
        self.clients: list[harness.TestClient] = []

    def connect(self) -> harness.TestClient:
        c = harness.TestClient(self)  # type: ignore[arg-type]
        for _ in range(50):
            self.pump_io()
        return c

    def pump_io(self) -> None:
        self.sup.scheduler.poll_io(0.0)

    def advance(self, seconds: float) -> None:
        self.sup.scheduler.run_for(seconds)


def test_an_ipv6_client_is_named_with_its_address_in_brackets() -> None:
    """The server named it `::1:41234` (in the recorder's MCP log, control events and log
    lines), which no tool takes back as an address and port."""
    if not socket.has_ipv6:  # pragma: no cover - every CI machine has ::1
        pytest.skip("no IPv6")
    rec = Recording()
    try:
        h = Harness(rec, host="::1")
    except OSError:  # pragma: no cover - a container with IPv6 turned off
        pytest.skip("cannot serve on ::1")
    c = h.connect()
    try:
        assert c.ask("robot:control.acquire=(op)") == ""
        peer = f"[::1]:{c.sock.getsockname()[1]}"
        assert ("in", peer, b"robot:control.acquire=(op)") in rec.seen
    finally:
        c.sock.close()
        h.sup.shutdown()


def test_every_point_is_seen() -> None:
    rec = Recording()
    h = Harness(rec)
    c = h.connect()
    peer = f"127.0.0.1:{c.sock.getsockname()[1]}"
    assert c.ask("robot:control.acquire=(op)demo:motor.vel=(50)") == ""
    h.advance(0.3)
    assert c.ask("demo:demo.get=()").startswith("demo:motor.vel=(50)")
    h.advance(1.0)  # silent for longer than the 0.5 s watchdog
    h.world.unplugged.add("io2")
    h.advance(0.05)
    h.sup.shutdown()
    c.sock.close()
    seen = rec.seen
    started = seen.index(("started",))
    stopping = seen.index(("stopping",))
    assert seen[-1] == ("control", "none") and stopping > started  # the owner's link closed
    assert ("module", "demo", "ok") in seen[:started] and ("module", "arm", "ok") in seen
    assert ("in", peer, b"robot:control.acquire=(op)demo:motor.vel=(50)") in seen
    assert ("out", peer, b"") in seen
    assert ("control", "op") in seen
    assert ("command", "io", "demo.motor", 0.5) in seen
    assert ("watchdog", "armed", "motion") in seen
    assert ("watchdog", "tripped", "expired") in seen
    assert ("command", "io", "demo.motor", 0.0) in seen  # the trip stopped it
    assert ("bus_fault", "io2", "simulated device unplugged") in seen
    assert ("module", "arm", "fault") in seen
    assert rec.ticks >= 130
    assert len(rec.rows) >= 13  # 10 Hz
    _, health, demo = rec.rows[5]
    assert any(r.device == "watchdog" and r.prop == "state" for r in health)
    assert [(r.device, r.prop) for r in demo] == [("motor", "vel"), ("lamp", "on")]


def test_unobserved_points_cost_nothing() -> None:
    h = Harness(None)
    sup = h.sup
    assert sup.server.on_message_in is None and sup.server.on_message_out is None
    assert all(b.on_command is None for b in sup.buses.values())
    assert all(s.on_change is None for s in sup.slots.values())
    assert sup.watchdog.on_change is None and sup.robot.on_control is None
    assert sup.bus_manager.on_fault is None and sup.scheduler.on_tick is None
    sup.shutdown()


class WatchdogTimes(Observer):
    def __init__(self) -> None:
        self.changes: list[tuple[float, str, str]] = []

    def watchdog(self, t: float, state: str, why: str) -> None:
        self.changes.append((t, state, why))


def test_robot_stop_disarms_the_watchdog_at_the_supervisors_time() -> None:
    """`robot:robot.stop=()` used to disarm the watchdog at time 0.0 (a default argument),
    so a recording put that event hours before the run on the robot's monotonic clock."""
    rec = WatchdogTimes()
    h = Harness(rec)
    h.clock.advance(100.0)
    c = h.connect()
    assert c.ask("demo:motor.vel=(50)") == ""
    h.advance(0.2)
    assert c.ask("robot:robot.stop=()") == ""
    now = h.clock.now()
    h.sup.shutdown()
    c.sock.close()
    assert [s for _, s, _ in rec.changes] == ["armed", "idle"]
    assert rec.changes[-1][0] == pytest.approx(now, abs=0.01)
