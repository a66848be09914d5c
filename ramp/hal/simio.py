"""`sim` driver: HAL channels bound to a simulated world, for `ramp run --sim`.

The world (the MARTE physics model in `firmware_like/`) is handed in by the one simulation
entry point; this module never imports it. Channels are found by their label,
`module.device` as in YAML (`base.lf_wheel`), so the world exposes its signals under the
same names. This is the HAL-level emulator for boards whose transport cannot be emulated
(Phidget USB); Sabertooth and CAN buses are simulated at the wire instead.
"""

from __future__ import annotations

from typing import Any, ClassVar, Protocol

from ramp.errors import DeviceError
from ramp.hal.interfaces import (
    AnalogInput,
    BridgeInput,
    Bus,
    DigitalInput,
    DigitalOutput,
    MotorChannel,
)
from ramp.schema import Field


class SimWorld(Protocol):
    """What a simulated world offers the sim driver; signals are named `module.device`."""

    def set_motor(self, name: str, duty: float) -> None: ...
    def read_analog(self, name: str) -> float: ...
    def read_digital(self, name: str) -> bool: ...
    def write_digital(self, name: str, on: bool) -> None: ...
    def read_bridge(self, name: str) -> float: ...
    def bus_present(self, bus: str) -> bool: ...


class _Motor(MotorChannel):
    def _apply(self, duty: float) -> None:
        bus = self.bus
        assert isinstance(bus, SimBus)
        if bus.is_open:
            bus.world.set_motor(self.label, duty)


class _Analog(AnalogInput):
    def read(self) -> float:
        bus = self.bus
        assert isinstance(bus, SimBus)
        return bus.world.read_analog(self.label)


class _DigitalIn(DigitalInput):
    def read(self) -> bool:
        bus = self.bus
        assert isinstance(bus, SimBus)
        return bus.world.read_digital(self.label)


class _DigitalOut(DigitalOutput):
    def _apply(self, on: bool) -> None:
        bus = self.bus
        assert isinstance(bus, SimBus)
        if bus.is_open:
            bus.world.write_digital(self.label, on)


class _Bridge(BridgeInput):
    def read(self) -> float:
        bus = self.bus
        assert isinstance(bus, SimBus)
        return bus.world.read_bridge(self.label)


_CLASSES: dict[str, type] = {
    "motor": _Motor, "analog_in": _Analog, "digital_in": _DigitalIn,
    "digital_out": _DigitalOut, "bridge_in": _Bridge,
}


class SimBus(Bus):
    """A bus whose channels are signals of a simulated world.

    When it stands in for a real driver under `--sim`, the device entries keep their real
    channel keys (address, channel, ...); this driver ignores them and wires by label.
    """

    driver_name = "sim"
    fields: ClassVar[dict[str, Field]] = {}
    channel_fields: ClassVar[dict[str, dict[str, Field]]] = {k: {} for k in _CLASSES}

    def __init__(self, name: str, params: dict[str, Any], world: SimWorld | None = None) -> None:
        super().__init__(name, params)
        if world is None:
            raise DeviceError(name, "the sim driver runs only under `ramp run --sim`")
        self.world = world

    def _make_channel(self, kind: str, label: str, spec: dict[str, Any]) -> Any:
        return _CLASSES[kind](self, label)

    def _open(self, now: float) -> None:
        if not self.world.bus_present(self.name):
            raise DeviceError(self.name, "simulated device unplugged")
        for m in self.motors:
            self.world.set_motor(m.label, m.duty)

    def _tick(self, now: float, dt: float) -> None:
        if not self.world.bus_present(self.name):
            raise DeviceError(self.name, "simulated device unplugged")

    def _stop_motors(self) -> None:
        for m in self.motors:
            self.world.set_motor(m.label, 0.0)

    def _close(self) -> None:
        pass
