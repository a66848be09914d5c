"""Every registered driver: builds from YAML, stops its motors on close, rejects bad values."""

from __future__ import annotations

import math
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from firmware_like.odrive import ODriveEmulator
from firmware_like.pty_link import PtyLink
from firmware_like.sabertooth import SabertoothEmulator, SabertoothPtyDevice
from ramp.config import parse_config
from ramp.hal import driver_class
from ramp.hal.interfaces import Bus, MotorChannel
from ramp.hal.simio import SimBus
from ramp.registry import drivers
from tests.harness import FakeWorld


@dataclass
class Rig:
    bus: Bus
    motor_spec: dict[str, Any] | None  # a valid motor channel, None when the driver has none
    bad_yaml: str  # a config with one out-of-range channel key ...
    bad_key: str  # ... and the key path its error must name
    observed: Callable[[], float]  # the duty the device sees now
    pump: Callable[[float], None]  # let the device and the bus exchange bytes at `now`
    cleanup: Callable[[], None]


def _from_yaml(driver: str, body: str) -> dict[str, Any]:
    cfg, errors = parse_config(f"buses:\n  b: {{driver: {driver}{body}}}\n", "r.yaml")
    assert not errors, errors
    assert cfg is not None
    return dict(cfg.buses["b"].params)


def sabertooth_rig(tmp_path: Path) -> Rig:
    link = PtyLink("b", tmp_path)
    emu = SabertoothEmulator((128,))
    dev = SabertoothPtyDevice(link, emu)
    bus = driver_class("sabertooth")("b", _from_yaml("sabertooth", f", port: {link.path}"))

    def pump(now: float) -> None:
        bus.tick(now, 0.01)
        for _ in range(50):
            if not dev.service(now):
                break

    bad = ("buses:\n  b: {driver: sabertooth, port: x}\nmodules:\n  demo:\n"
           "    motor: {bus: b, address: 136, motor: 1}\n    lamp: {bus: b}\n")
    return Rig(bus, {"address": 128, "motor": 1}, bad, "modules.demo.motor.address",
               lambda: emu.duty(128, 1), pump, link.close)


def can_rig(tmp_path: Path) -> Rig:
    channel = f"registry-{uuid.uuid4().hex}"
    emu = ODriveEmulator(channel, [1])
    bus = driver_class("can")("b", _from_yaml("can", f", channel: {channel}, max_vel: 10.0"))

    def pump(now: float) -> None:
        emu.tick(now)
        bus.tick(now, 0.01)
        emu.tick(now)

    bad = ("buses:\n  b: {driver: can, channel: c}\nmodules:\n  demo:\n"
           "    motor: {bus: b, node_id: 64}\n    lamp: {bus: b}\n")
    return Rig(bus, {"node_id": 1}, bad, "modules.demo.motor.node_id",
               lambda: emu.axes[1].input_vel / 10.0, pump, emu.close)


def phidget_rig(tmp_path: Path) -> Rig:
    from tests.unit.test_phidget_driver import FakeBoard

    board = FakeBoard()
    bus = driver_class("phidget")("b", _from_yaml("phidget", ", serial: 1234"), api=board.api)
    bad = ("buses:\n  b: {driver: phidget}\nmodules:\n  demo:\n"
           "    motor: {bus: b}\n    lamp: {bus: b, channel: 8}\n")
    return Rig(bus, None, bad, "modules.demo.lamp.channel", lambda: 0.0,
               lambda now: None, lambda: None)


def sim_rig(tmp_path: Path) -> Rig:
    world = FakeWorld()
    bus = SimBus("b", _from_yaml("sim", ""), world=world)
    bad = ("buses:\n  b: {driver: sim}\nmodules:\n  demo:\n"
           "    motor: {bus: b, address: 1}\n    lamp: {bus: b}\n")  # sim takes no keys
    return Rig(bus, {}, bad, "modules.demo.motor.address",
               lambda: world.motors.get("m.motor", 0.0), lambda now: None, lambda: None)


RIGS: dict[str, Callable[[Path], Rig]] = {
    "sabertooth": sabertooth_rig, "can": can_rig, "phidget": phidget_rig, "sim": sim_rig,
}


def ramp_drivers() -> set[str]:
    """The drivers RAMP itself registers (an installed plugin may add more)."""
    return {n for n in drivers().names() if drivers().entry(n).distribution == "ramp"}


def test_every_registered_driver_is_covered_here() -> None:
    assert set(RIGS) == ramp_drivers()


def test_an_unknown_driver_lists_the_valid_ones() -> None:
    _, errors = parse_config("buses:\n  b: {driver: nope}\n", "r.yaml")
    # Every installed driver: RAMP's own and the plugins' (the example winchbox).
    assert str(errors[0]) == ("r.yaml:2: buses.b.driver: unknown driver 'nope' (expected one "
                              f"of: {', '.join(drivers().names())})")
    assert {"can", "phidget", "sabertooth", "sim"} <= set(drivers().names())


@pytest.fixture(params=sorted(RIGS))
def rig(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Rig]:
    r = RIGS[request.param](tmp_path)
    yield r
    r.bus.close()
    r.cleanup()


def test_builds_from_yaml_with_every_channel_kind(rig: Rig) -> None:
    bus = rig.bus
    assert bus.driver_name in drivers()
    assert isinstance(bus, driver_class(bus.driver_name))
    assert bus.channel_fields, "a driver offers at least one channel kind"
    assert not bus.is_open


def test_motor_stops_on_close(rig: Rig) -> None:
    if rig.motor_spec is None:
        assert "motor" not in rig.bus.channel_fields
        return
    motor: MotorChannel = rig.bus.channel("motor", "m.motor", rig.motor_spec)
    now = 0.0
    rig.bus.open(now)
    for _ in range(30):  # let boards that answer asynchronously come up
        now += 0.01
        rig.pump(now)
    motor.set_duty(0.6)
    rig.pump(now + 0.01)
    assert rig.observed() == pytest.approx(0.6, abs=0.01)
    rig.bus.close()
    rig.pump(now + 0.02)
    assert rig.observed() == 0.0
    rig.bus.close()  # idempotent


def test_rejects_out_of_range_values(rig: Rig) -> None:
    if rig.motor_spec is not None:
        motor: MotorChannel = rig.bus.channel("motor", "m.motor", rig.motor_spec)
        for bad in (1.5, -1.01, math.nan, math.inf):
            with pytest.raises(ValueError):
                motor.set_duty(bad)
        assert motor.duty == 0.0
    _, errors = parse_config(rig.bad_yaml, "r.yaml")
    assert any(f"{rig.bad_key}:" in str(e) for e in errors), errors
