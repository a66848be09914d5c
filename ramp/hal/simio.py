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
    ServoChannel,
)
from ramp.schema import Field


class SimWorld(Protocol):
    """What a simulated world offers the sim driver; signals are named `module.device`.

    A world may also have an int `revision` that moves on whenever what it reads back may
    have changed (the MARTE model: each step); the driver then samples only when it moved.
    Without one, every tick samples."""

    def set_motor(self, name: str, duty: float) -> None: ...
    def read_analog(self, name: str) -> float: ...
    def read_digital(self, name: str) -> bool: ...
    def write_digital(self, name: str, on: bool) -> None: ...
    def read_bridge(self, name: str) -> float: ...
    def bus_present(self, bus: str) -> bool: ...


class ServoWorld(Protocol):
    """What a world with RC servos adds (optional: a world without them gets none)."""

    def set_servo(self, name: str, target_deg: float | None, speed_dps: float) -> None: ...
    def read_servo(self, name: str) -> float: ...


class _Input:
    """An input signal: `value` is the sample the bus's last tick took from the world."""

    value: Any
    read_world: str  # the SimWorld method that samples it

    def sample(self, world: SimWorld) -> None:
        self.value = getattr(world, self.read_world)(self.label)  # type: ignore[attr-defined]


class _Analog(_Input, AnalogInput):
    read_world = "read_analog"
    value = 0.0

    def read(self) -> float:
        return float(self.value)


class _DigitalIn(_Input, DigitalInput):
    read_world = "read_digital"
    value = False

    def read(self) -> bool:
        return bool(self.value)


class _Bridge(_Input, BridgeInput):
    read_world = "read_bridge"
    value = 0.0

    def read(self) -> float:
        return float(self.value)


class _Servo(ServoChannel):
    """A servo whose controller is the world's: commands go to `set_servo`, the position it
    reports comes from `read_servo` at each tick."""

    def sample(self, world: SimWorld) -> None:
        self.position = float(world.read_servo(self.label))  # type: ignore[attr-defined]


_CLASSES: dict[str, type] = {
    "motor": MotorChannel, "analog_in": _Analog, "digital_in": _DigitalIn,
    "digital_out": DigitalOutput, "bridge_in": _Bridge, "servo": _Servo,
}


class SimBus(Bus):
    """A bus whose channels are signals of a simulated world.

    When it stands in for a real driver under `--sim`, the bus and device entries keep their
    real keys (port, address, channel, ...); this driver ignores them and wires by label.
    Inputs are sampled from the world in `tick` (and at open), as a real board's samples
    arrive, so readings change only inside a tick.
    """

    driver_name = "sim"
    fields: ClassVar[dict[str, Field]] = {}
    channel_fields: ClassVar[dict[str, dict[str, Field]]] = {k: {} for k in _CLASSES}

    def __init__(self, name: str, params: dict[str, Any], world: SimWorld | None = None) -> None:
        super().__init__(name, params)
        if world is None:
            raise DeviceError(name, "the sim driver runs only under `ramp run --sim`")
        self.world = world
        self.inputs: list[_Input] = []
        self._sampled: int | None = None  # the world's revision the inputs hold

    def _make_channel(self, kind: str, label: str, spec: dict[str, Any]) -> Any:
        ch = _CLASSES[kind](self, label)
        if isinstance(ch, (_Input, _Servo)):
            self.inputs.append(ch)  # type: ignore[arg-type]
        return ch

    def _open(self, now: float) -> None:
        if not self.world.bus_present(self.name):
            raise DeviceError(self.name, "simulated device unplugged")
        self._sampled = None
        for m in self.motors:
            self.world.set_motor(m.label, m.duty)
        for o in self.outputs:
            self.world.write_digital(o.label, o.state)
        for sv in self.servos:
            self._servo_changed(sv)
        self._sample()

    def _tick(self, now: float, dt: float) -> None:
        if not self.world.bus_present(self.name):
            raise DeviceError(self.name, "simulated device unplugged")
        self._sample()

    def _sample(self) -> None:
        world = self.world
        revision = getattr(world, "revision", None)
        if revision is not None and revision == self._sampled:
            return
        for ch in self.inputs:
            ch.sample(world)
        self._sampled = revision

    def _motor_changed(self, ch: MotorChannel) -> None:
        self.world.set_motor(ch.label, ch.duty)

    def _output_changed(self, ch: DigitalOutput) -> None:
        self.world.write_digital(ch.label, ch.state)

    def _servo_changed(self, ch: ServoChannel) -> None:
        self.world.set_servo(ch.label, ch.target, ch.speed_dps)  # type: ignore[attr-defined]

    def _stop_motors(self) -> None:
        for m in self.motors:
            self.world.set_motor(m.label, 0.0)
        for sv in self.servos:
            self._servo_changed(sv)

    def _close(self) -> None:
        pass
