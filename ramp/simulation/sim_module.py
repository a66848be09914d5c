"""The `sim` module (SPEC 12): what real hardware does to a robot, injected over MCP.

Under `ramp run --sim`, in `ramp sim mission` and in the tests' simulated robots, a test, a
trainer or an operator in training makes the simulated hardware misbehave while the robot
runs, and watches the real backend cope: the lift jams (`sim:lift.jam=(1)`) and the real
stall detection latches; a bus's device vanishes (`sim:bus.unplug=(ble_motors)`) and the
real hot-plug path faults its modules and re-attaches them after `sim:bus.plug`; an input
reads a value (`sim:input.set=(base,battery,10.5)`, a pressed button) until cleared. In a
mission the LIDAR can go blind and the IMU's mount can shift.

Every request is kind `state`: owner-only while someone owns control, recorded like any
other. Inputs are found through the wiring (the config's modules and devices), buses by
their config names, so a robot other than MARTE gets the same requests for its own wiring.
The module only reaches the emulators through the backplane's named hooks (`unplug`,
`plug`, `signals.set_input`, the world's `jam_lift`) and the mission rig's (`blind`,
`shift`). A bad argument is `bad_params` naming what exists, and changes nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ramp.errors import RequestError
from ramp.layers.module_distribution import Function, Module, Property
from ramp.mcp.params import FlagParam, FloatParam, NameParam

if TYPE_CHECKING:
    from ramp.simulation.backplane import SimBackplane

NAME = "sim"
#: The largest magnitude `sim:input.set` takes: wider than any real board's raw range (a
#: bridge input reads up to 1000 mV/V); 1e308 was taken, and `get` then answered with a number
#: of three hundred digits.
MAX_INPUT = 1000.0
#: HAL kinds `sim:input.set` accepts (the inputs a module reads).
INPUT_KINDS = ("digital_in", "analog_in", "bridge_in")
#: Largest IMU mount rotation `sim:imu.shift` accepts (deg).
MAX_SHIFT_DEG = 90.0


def _bad(detail: str) -> RequestError:
    return RequestError("bad_params", detail)


class SimModule(Module):
    """`sim:lift.jam`, `sim:bus.unplug/plug`, `sim:input.set/clear` on a backplane; the
    mission adds `sim:lidar.blind` and `sim:imu.shift` (`add_sensor_faults`)."""

    def __init__(self, backplane: SimBackplane) -> None:
        super().__init__(NAME)
        self.backplane = backplane
        self.config = backplane.config
        self.jammed = 0
        self.blind = 0
        self.shifted_deg = 0.0
        name = NameParam()
        jam = getattr(backplane.world, "jam_lift", None)
        if jam is not None:
            self._jam: Callable[[bool], None] = jam
            self.add(Function("lift", "jam", (FlagParam(),), self._lift_jam, "state",
                              "1: the lift actuator stalls in place; 0: it moves again"))
            self.prop(Property("lift", "jam", "int", lambda: self.jammed))
        self.add(Function("bus", "unplug", (name,), self._unplug, "state",
                          "the bus's device vanishes (hot plug)"))
        self.add(Function("bus", "plug", (name,), self._plug, "state",
                          "the bus's device comes back"))
        self.add(Function("input", "set", (name, name, FloatParam(-MAX_INPUT, MAX_INPUT)),
                          self._input_set, "state",
                          "an input reads VALUE until cleared (module, device, value)"))
        self.add(Function("input", "clear", (name, name), self._input_clear, "state",
                          "the input reads the simulated world again (module, device)"))
        self.prop(Property("bus", "unplugged", "int", lambda: len(backplane.unplugged)))
        self.prop(Property("input", "overrides", "int",
                           lambda: len(backplane.signals.overrides)))

    def add_sensor_faults(self, blind: Callable[[bool], None],
                          shift: Callable[[float], None]) -> None:
        """The mission rig's sensors: `sim:lidar.blind=(0|1)`, `sim:imu.shift=(DEG)`."""
        self._blind, self._shift = blind, shift
        self.add(Function("lidar", "blind", (FlagParam(),), self._lidar_blind, "state",
                          "1: every LIDAR beam returns nothing; 0: it sees again"))
        self.add(Function("imu", "shift", (FloatParam(-MAX_SHIFT_DEG, MAX_SHIFT_DEG),),
                          self._imu_shift, "state", "the IMU mount rotates DEG degrees now"))
        self.prop(Property("lidar", "blind", "int", lambda: self.blind))
        self.prop(Property("imu", "shift", "float", lambda: round(self.shifted_deg, 3), "deg"))

    # -- requests -----------------------------------------------------------------------------
    def _lift_jam(self, on: int) -> None:
        self._jam(bool(on))
        self.jammed = on

    def _unplug(self, bus: str) -> None:
        self.backplane.unplug(self._simulated_bus(bus))

    def _plug(self, bus: str) -> None:
        bus = self._simulated_bus(bus)
        if bus in self.backplane.dead:
            raise _bad(f"bus {bus} stays dead: the emulator part behind it faulted")
        self.backplane.plug(bus)

    def _input_set(self, module: str, device: str, value: float) -> None:
        label, kind = self._input(module, device)
        if kind == "digital_in" and value not in (0.0, 1.0):
            raise _bad(f"{module}:{device} is a digital input: its value is 0 or 1")
        self.backplane.signals.set_input(label, value)

    def _input_clear(self, module: str, device: str) -> None:
        label, _ = self._input(module, device)
        self.backplane.signals.clear_input(label)

    def _lidar_blind(self, on: int) -> None:
        self._blind(bool(on))
        self.blind = on

    def _imu_shift(self, deg: float) -> None:
        self._shift(deg)
        self.shifted_deg += deg

    # -- checks (before anything changes) -----------------------------------------------------
    def _simulated_bus(self, bus: str) -> str:
        buses = self.config.buses
        if bus not in buses:
            raise _bad(f"no bus {bus}; buses: {' '.join(buses) or 'none'}")
        if not buses[bus].sim:
            raise _bad(f"bus {bus} keeps its real driver (sim: false): it is not simulated")
        return bus

    def _input(self, module: str, device: str) -> tuple[str, str]:
        """The input's signal label and HAL kind, from the wiring."""
        modules = self.config.modules
        mc = modules.get(module)
        if mc is None:
            raise _bad(f"no module {module}; modules: {' '.join(modules) or 'none'}")
        dc = mc.devices.get(device)
        inputs = [d for d, c in mc.devices.items() if c.kind in INPUT_KINDS]
        listed = " ".join(inputs) or "none"
        if dc is None:
            raise _bad(f"{module} has no device {device}; its inputs: {listed}")
        if dc.kind not in INPUT_KINDS:
            raise _bad(f"{module}:{device} is a {dc.kind} not an input; inputs: {listed}")
        self._simulated_bus(dc.bus)
        return f"{module}.{device}", dc.kind

    # -- Module -------------------------------------------------------------------------------
    def stop(self) -> None:
        """Nothing of the simulator's moves."""

    def is_moving(self) -> bool:
        return False

    def status(self) -> dict[str, Any]:
        """What is injected now (for tools and logs)."""
        return {"jammed": self.jammed, "unplugged": sorted(self.backplane.unplugged),
                "inputs": dict(self.backplane.signals.overrides), "blind": self.blind,
                "shift_deg": self.shifted_deg}
