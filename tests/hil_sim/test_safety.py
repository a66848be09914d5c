"""Lock-up and crash safety: the stall guard, and a SIGKILLed supervisor (partial HIL)."""

from __future__ import annotations

import logging
import signal
import socket
import threading
import time
from pathlib import Path

import pytest

from firmware_like.pty_link import PtyLink
from firmware_like.sabertooth import SabertoothEmulator, SabertoothPtyDevice
from ramp.clock import MonotonicClock
from ramp.hal.simio import SimBus
from ramp.runtime import build
from ramp.runtime.stall_guard import StallGuard
from tests.harness import DEMO_YAML, MARTE_YAML, FakeWorld, config_from
from tests.harness import ask_line as ask
from tests.harness import start_ramp as start


class RecordingWorld(FakeWorld):
    """Remembers which thread wrote each motor value."""

    def __init__(self) -> None:
        super().__init__()
        self.history: list[tuple[str, float, str]] = []

    def set_motor(self, name: str, duty: float) -> None:
        super().set_motor(name, duty)
        self.history.append((name, duty, threading.current_thread().name))


def test_a_stalled_task_has_its_motors_stopped_and_is_named(
        caplog: pytest.LogCaptureFixture) -> None:
    world = RecordingWorld()
    sup = build(config_from(DEMO_YAML), MonotonicClock(),
                     bus_factory=lambda bc: SimBus(bc.name, dict(bc.params), world=world),
                     host="127.0.0.1", port=0)
    sup.start()
    guard = StallGuard(sup, limit=0.1)
    guard.start()
    try:
        sup.slots["demo"].module._vel(50)  # the demo motor runs
        assert world.motors["demo.motor"] == 0.5
        stalled = {"done": False}

        def stuck_task(now: float, dt: float) -> None:
            if not stalled["done"]:
                stalled["done"] = True
                time.sleep(0.5)  # a task blocking the loop, on purpose

        sup.scheduler.add_task("stuck_task", 100, stuck_task)
        with caplog.at_level(logging.ERROR, logger="ramp.stall"):
            sup.scheduler.run_for(0.7)
    finally:
        guard.stop()
    assert sup.slots["demo"].module.vel == 0  # the module caught up with the wire
    from_guard = [h for h in world.history if h[2] == "ramp-stall-guard"]
    assert ("demo.motor", 0.0, "ramp-stall-guard") in from_guard
    assert guard.stalls == 1
    assert "stalled" in caplog.text and "stuck_task" in caplog.text
    assert sup.scheduler.stats.overruns >= 1
    assert "stuck_task" in sup.scheduler.stats.last_overrun_task
    sup.shutdown()


@pytest.mark.timeout(60)
def test_sigkill_leaves_the_motors_stopped_by_the_controller_timeout(tmp_path: Path) -> None:
    """The base's Sabertooth bus is real (`sim: false`) and wired to an emulator in this
    process; the rest of the robot is simulated. After SIGKILL nothing refreshes the
    controllers, and their own serial timeout (programmed at start-up) stops the motors."""
    link = PtyLink("base_motors", tmp_path)
    emu = SabertoothEmulator((128, 129))
    device = SabertoothPtyDevice(link, emu)
    text = MARTE_YAML.replace(
        "base_motors: {driver: sabertooth, port: /dev/ttyUSB0, baud: 9600, timeout: 0.5}",
        f"base_motors: {{driver: sabertooth, port: {link.path}, baud: 9600, timeout: 0.5,"
        " sim: false}")
    assert text != MARTE_YAML
    cfg = tmp_path / "bench.yaml"
    cfg.write_text(text)
    proc, host, port = start(["--sim", "--config", str(cfg), "--host", "127.0.0.1",
                              "--port", "0"], env={"TMPDIR": str(tmp_path)})
    try:
        with socket.create_connection((host, port), timeout=5) as s:
            assert ask(s, "base:base.drive=(70,0)") == ""
            end = time.monotonic() + 1.0
            while time.monotonic() < end:  # keep the watchdog fed, watch the wire
                assert ask(s, "") == ""
                device.service(time.monotonic())
                time.sleep(0.02)
            assert emu.timeout(128) == pytest.approx(0.5)
            assert emu.duty(128, 1) == pytest.approx(round(0.7 * 127) / 127, abs=1e-6)
            assert not emu.timed_out(128)
            proc.send_signal(signal.SIGKILL)
            killed = time.monotonic()
            proc.wait(timeout=5)
            stopped_at = None
            while time.monotonic() - killed < 2.0:
                device.service(time.monotonic())
                if all(emu.duty(a, m) == 0.0 for a in (128, 129) for m in (1, 2)):
                    stopped_at = time.monotonic()
                    break
                time.sleep(0.005)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=5)
        link.close()
    assert stopped_at is not None, "the emulated motors never stopped"
    # within the programmed 0.5 s timeout (counted from the last refresh, before the kill),
    # plus scheduling slack for a busy test machine
    assert stopped_at - killed <= 0.5 + 0.25
    assert emu.timed_out(128) and emu.timed_out(129)


class StuckInsideBus(SimBus):
    """A sim bus whose driver hangs for a while inside `tick` (a pyserial write that
    blocks, say); it records any `stop_motors` that reaches the driver meanwhile."""

    def __init__(self, name: str, params: dict[str, object], world: FakeWorld) -> None:
        super().__init__(name, params, world=world)
        self.hang_once = False
        self.inside = False
        self.entered_while_inside: list[str] = []

    def _tick(self, now: float, dt: float) -> None:
        if self.hang_once:
            self.hang_once = False
            self.inside = True
            time.sleep(0.4)  # the loop is stuck inside this driver, on purpose
            self.inside = False
        super()._tick(now, dt)

    def _stop_motors(self) -> None:
        if self.inside:
            self.entered_while_inside.append(threading.current_thread().name)
        super()._stop_motors()


def test_the_stall_guard_never_writes_through_a_driver_the_loop_is_inside(
        caplog: pytest.LogCaptureFixture) -> None:
    """The guard used to call every driver from its thread with no lock, while the loop
    could be inside the same pyserial object. Now it waits a moment for each bus's lock,
    stops the others, and leaves the stuck one to its controller's own timeout."""
    world = RecordingWorld()
    buses: dict[str, SimBus] = {}

    def factory(bc: object) -> SimBus:
        name = bc.name  # type: ignore[attr-defined]
        bus = (StuckInsideBus(name, {}, world) if name == "io"
               else SimBus(name, {}, world=world))
        buses[name] = bus
        return bus

    sup = build(config_from(DEMO_YAML), MonotonicClock(), bus_factory=factory,
                     host="127.0.0.1", port=0)
    sup.start()
    guard = StallGuard(sup, limit=0.1)
    guard.start()
    stuck = buses["io"]
    assert isinstance(stuck, StuckInsideBus)
    try:
        sup.slots["demo"].module._vel(50)
        sup.slots["arm"].module._vel(50)
        sup.scheduler.run_for(0.1)
        stuck.hang_once = True
        with caplog.at_level(logging.ERROR):
            sup.scheduler.run_for(0.7)
    finally:
        guard.stop()
    assert stuck.entered_while_inside == []
    assert ("arm.motor", 0.0, "ramp-stall-guard") in world.history  # the free bus stopped
    assert "bus io: the tick loop is stuck inside its driver" in caplog.text
    assert world.motors["demo.motor"] == 0.0  # the loop stopped it when it came back
    assert sup.watchdog.state == "tripped"
    sup.shutdown()
