"""An emulator part that raises faults its own part, not all the physics (issue 33 item 1).

MARTE on the `--sim` backplane with a third module, `demo`, whose emulator part (registered
as a plugin registers one, `module.demo` in `ramp.emulators`) raises in its step. Before,
`World.step` let the exception out: the `sim.world` task raised on every tick, so no part was
stepped again (MARTE stood still whatever its wheels were told) and the traceback repeated a
hundred times a second. Now the broken part is faulted on its own: one traceback, its
device goes dead on its wire (its bus unplugged) so the backend faults that bus and module,
and MARTE's physics keeps stepping.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import Any

import pytest

from ramp import registry
from tests.harness import MARTE_YAML, SimHarness, value

YAML = MARTE_YAML.replace(
    "\nmodules:\n",
    "\n  demo_io: {driver: sim}\nmodules:\n  demo: {motor: {bus: demo_io}, "
    "lamp: {bus: demo_io}}\n", 1)


class BrokenPart:
    """A plugin's physics part for the demo module whose step raises from its third call."""

    steps = 0

    def __init__(self) -> None:
        self.duty = 0.0

    def set_motor(self, name: str, duty: float) -> None:
        if name != "demo.motor":
            raise KeyError(name)
        self.duty = duty

    def write_digital(self, name: str, on: bool) -> None:
        if name != "demo.lamp":
            raise KeyError(name)

    def step(self, dt: float) -> None:
        BrokenPart.steps += 1
        if BrokenPart.steps >= 3:
            raise ZeroDivisionError("a bug in the plugin's physics")


def broken_part(ctx: Any, module: str, config: Any) -> BrokenPart:
    return BrokenPart()


@pytest.fixture
def h(monkeypatch: pytest.MonkeyPatch) -> Iterator[SimHarness]:
    installed = registry.Registry("ramp.emulators")
    entries = [installed.entry(name) for name in installed.names()]
    entries.append(registry.Entry("module.demo", f"{__name__}:broken_part", "test-plugin"))
    monkeypatch.setitem(registry._REGISTRIES, "ramp.emulators",
                        registry.Registry("ramp.emulators", entries))
    BrokenPart.steps = 0
    harness = SimHarness(YAML)
    yield harness
    harness.close()


def test_a_part_that_raises_faults_its_own_module_and_the_rest_keeps_stepping(
        h: SimHarness, caplog: pytest.LogCaptureFixture) -> None:
    c = h.connect()
    assert "robot:demo.state=(ok)" in c.ask("robot:robot.get=()")
    assert c.ask("base:base.drive=(60,0)") == ""
    x0 = h.world.x
    with caplog.at_level(logging.ERROR, logger="ramp.sim"):
        for _ in range(10):
            h.advance(0.1)
            assert c.ask("") == ""  # keep the watchdog fed
    # One traceback for the part, however many ticks followed.
    raised = [r for r in caplog.records if "raised in step" in r.getMessage()]
    assert len(raised) == 1 and raised[0].exc_info is not None
    assert BrokenPart.steps == 3  # never stepped again once it raised
    # Its device went dead on its wire: the backend faulted that bus and the demo module ...
    health = c.ask("robot:robot.get=()")
    assert "robot:demo.state=(fault)" in health
    assert c.ask("demo:motor.vel=(10)").startswith("demo:motor.error=(fault,")
    assert "demo_io" in h.backplane.dead
    # ... and nothing else: MARTE's physics kept stepping and the base still drives.
    assert "robot:base.state=(ok)" in health and "robot:ble.state=(ok)" in health
    assert h.world.x > x0 + 0.1
    assert value(c.ask("base:base.get=()"), "base:lf_wheel.vel") == "60"
    # A dead bus stays dead: `sim:bus.plug` says why instead of reviving it.
    assert c.ask("sim:bus.plug=(demo_io)").startswith("sim:bus.error=(bad_params,")
    h.advance(2.1)
    assert "robot:demo.state=(fault)" in c.ask("robot:robot.get=()")


def no_part(ctx: Any, module: str, config: Any) -> BrokenPart:
    raise RuntimeError("the plugin's emulator cannot be built")


def test_an_emulator_that_fails_to_build_leaves_its_buses_dead_and_the_rest_runs(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    installed = registry.Registry("ramp.emulators")
    entries = [installed.entry(name) for name in installed.names()]
    entries.append(registry.Entry("module.demo", f"{__name__}:no_part", "test-plugin"))
    monkeypatch.setitem(registry._REGISTRIES, "ramp.emulators",
                        registry.Registry("ramp.emulators", entries))
    with caplog.at_level(logging.ERROR, logger="ramp.sim"):
        h = SimHarness(YAML)
    try:
        assert any("failed to load or build" in r.getMessage() and r.exc_info
                   for r in caplog.records)
        c = h.connect()
        health = c.ask("robot:robot.get=()")
        assert "robot:demo.state=(ok)" not in health
        assert "robot:base.state=(ok)" in health and "robot:ble.state=(ok)" in health
        assert c.ask("base:base.drive=(60,0)") == ""
        x0 = h.world.x
        for _ in range(5):
            h.advance(0.1)
            assert c.ask("") == ""
        assert h.world.x > x0 + 0.05
    finally:
        h.close()


class _RaisingTimers:
    def tick(self, now: float) -> None:
        raise ZeroDivisionError("a bug in the emulator's timers")


class _BrokenWireDevice:
    """The pty device with its reads or its timers raising (a stand-in: the compiled
    emulator classes are closed to monkeypatching)."""

    def __init__(self, real: Any, where: str) -> None:
        self.link = real.link
        self.emulator = _RaisingTimers() if where == "tick" else real.emulator
        self._real, self._where = real, where

    def service(self, now: float) -> None:
        if self._where == "service":
            raise ZeroDivisionError("a bug in the emulator's reader")
        self._real.service(now)


@pytest.mark.parametrize("where", ["tick", "service"])
def test_a_wire_emulator_that_raises_kills_only_its_own_bus(
        where: str, caplog: pytest.LogCaptureFixture) -> None:
    """The Sabertooth emulator behind the BLE's pty raises in its timers or reading its wire:
    that bus goes dead (one traceback), the BLE faults through its real driver, the base and
    the physics carry on."""
    h = SimHarness()
    try:
        c = h.connect()
        bp = h.backplane
        with caplog.at_level(logging.ERROR, logger="ramp.sim"):
            bp.sabertooth["ble_motors"] = _BrokenWireDevice(bp.sabertooth["ble_motors"], where)
            bp._watched.pop("ble_motors", None)  # the loop's reader goes to the stand-in
            assert c.ask("base:base.drive=(60,0)ble:chain.vel=(20)") == ""
            x0 = h.world.x
            for _ in range(15):
                h.advance(0.1)
                assert c.ask("") == ""
        raised = [r for r in caplog.records if "emulator of bus ble_motors raised" in
                  r.getMessage()]
        assert len(raised) == 1 and raised[0].exc_info is not None
        health = c.ask("robot:robot.get=()")
        assert "robot:ble.state=(fault)" in health and "robot:base.state=(ok)" in health
        # still driving (held to a creep: with the lift unread the interlocks fail closed)
        assert h.world.x > x0 + 0.02
        assert "ble_motors" in bp.dead
    finally:
        h.close()
