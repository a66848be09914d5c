"""The one simulation entry point: wires firmware_like emulators and physics to real drivers.

`ramp run --sim` replaces every bus, except those marked `sim: false`, by its emulator:
Sabertooth buses by the Sabertooth firmware emulator behind a pty (the real driver writes
real packets), CAN buses by the ODrive emulator on python-can's virtual bus, and Phidget
boards by the HAL-level sim driver (USB cannot be emulated). All of them move one MARTE
physics model, stepped by a scheduler task on the supervisor's clock.

The model knows MARTE's signals (`base.lf_wheel`, `ble.lift_pot`, ...). A config with other
module names, or devices the model has no physics for, still runs: those signals go to a
plain sim driver's world instead (motors and outputs are recorded, inputs read 0), so a new
robot's wiring can be tried under --sim before it has a physics model.
"""

from __future__ import annotations

import logging
import select
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from firmware_like.marte import MarteWorld
from ramp.config import BusConfig, Config
from ramp.hal.interfaces import Bus
from ramp.hal.simio import SimBus
from ramp.runtime import default_bus_factory

if TYPE_CHECKING:
    from ramp.runtime.supervisor import Supervisor

log = logging.getLogger("ramp.sim")

#: How often `ramp run --sim` steps the physics (s^-1). One step of the MARTE model costs
#: about as much as the rest of a tick together, and its longest piece is 0.05 s
#: (`MarteParams.max_step`), so 20 Hz is one piece per step: the supervisor's own ticks stay
#: cheap and the model its own. The emulated devices (paced wire, serial timeouts) are
#: serviced every tick regardless. `ramp sim …` and the tests step it every tick.
RUN_PHYSICS_HZ = 20.0


def _readable(fds: list[int]) -> set[int]:
    """Which of `fds` have input now (an unplugged pty, fd -1, never has)."""
    fds = [fd for fd in fds if fd >= 0]
    if not fds:
        return set()
    readable, _, _ = select.select(fds, [], [], 0)
    return set(readable)


class PlainSignals:
    """The world of a plain sim driver: commands are remembered, inputs read zero."""

    def __init__(self) -> None:
        self.motors: dict[str, float] = {}
        self.outputs: dict[str, bool] = {}

    def set_motor(self, name: str, duty: float) -> None:
        self.motors[name] = duty

    def read_analog(self, name: str) -> float:
        return 0.0

    def read_digital(self, name: str) -> bool:
        return False

    def write_digital(self, name: str, on: bool) -> None:
        self.outputs[name] = on

    def read_bridge(self, name: str) -> float:
        return 0.0

    def bus_present(self, bus: str) -> bool:
        return True


class RoutedSignals:
    """What the sim buses and the emulators drive: the physics model for every signal it
    knows (it raises KeyError for the others), plain signals for the rest."""

    def __init__(self, model: MarteWorld) -> None:
        self.model = model
        self.plain = PlainSignals()
        self._plain_names: set[str] = set()
        #: Inputs the `sim` module holds at a value (`sim:input.set`): name -> quantity.
        self.overrides: dict[str, float] = {}
        self._override_changes = 0

    def _route(self, method: str, name: str, *args: Any) -> Any:
        if name not in self._plain_names:
            try:
                return getattr(self.model, method)(name, *args)
            except KeyError:
                self._plain_names.add(name)
                log.info("sim: %s is not a signal of the physics model; it is simulated "
                         "plainly (commands recorded, inputs read 0)", name)
        return getattr(self.plain, method)(name, *args)

    def set_motor(self, name: str, duty: float) -> None:
        self._route("set_motor", name, duty)

    def read_analog(self, name: str) -> float:
        if name in self.overrides:
            return float(self._overridden(name))
        return float(self._route("read_analog", name))

    def read_digital(self, name: str) -> bool:
        if name in self.overrides:
            return bool(self._overridden(name))
        return bool(self._route("read_digital", name))

    def write_digital(self, name: str, on: bool) -> None:
        self._route("write_digital", name, on)

    def read_bridge(self, name: str) -> float:
        if name in self.overrides:
            return float(self._overridden(name))
        return float(self._route("read_bridge", name))

    def bus_present(self, bus: str) -> bool:
        return self.model.bus_present(bus)

    # -- the `sim` module's hooks -----------------------------------------------------------
    def set_input(self, name: str, quantity: float) -> None:
        """Input `name` reads as if it sensed `quantity` until `clear_input`."""
        self.overrides[name] = quantity
        self._override_changes += 1

    def clear_input(self, name: str) -> None:
        if self.overrides.pop(name, None) is not None:
            self._override_changes += 1

    def _overridden(self, name: str) -> float | bool:
        """An overridden input's reading: through the model's sensor (the battery's rail
        volts become pin volts) where the model knows it, else the value itself."""
        quantity = self.overrides[name]
        if name not in self._plain_names:
            try:
                return self.model.sensor_reading(name, quantity)
            except KeyError:
                pass
        return quantity

    @property
    def revision(self) -> int:
        """Moves on with the model and with every override: plain signals never change
        what they read back."""
        return int(self.model.revision) + self._override_changes


class SimBackplane:
    """Builds the simulated world and the bus for each config entry."""

    def __init__(self, config: Config, world: MarteWorld | None = None,
                 wire_level: bool = True, physics_hz: float | None = None,
                 read_in_wait: bool = True) -> None:
        """`physics_hz`: how often the world is stepped (None: every tick, the default, so a
        simulated run is the same at any tick rate); the emulated devices are serviced every
        tick whatever it is, so their serial timeouts stay exact.

        `read_in_wait`: an emulator behind a pty reads the driver's bytes the moment they
        arrive (the loop's wait watches the pty), as the tests and `ramp sim` want; False
        reads them once per tick instead, for `ramp run --sim` on the wall clock, where a pty
        in the loop's wait is polled by the kernel at every request the supervisor answers
        (about 1 µs each, 5 % of a round trip) to save the emulators a few milliseconds."""
        self.config = config
        self.physics_hz = physics_hz
        self.read_in_wait = read_in_wait
        self._physics_dt = 0.0
        self.world = world if world is not None else MarteWorld()
        #: The signals buses and emulators drive: the model's, and plain ones for the rest.
        self.signals = RoutedSignals(self.world)
        self.wire_level = wire_level
        self.devices: list[Any] = []  # emulated devices serviced every tick
        self._tmp = tempfile.TemporaryDirectory(prefix="ramp-sim-")
        self.dir = Path(self._tmp.name)
        self.services: list[Callable[[float], Any]] = []
        #: Emulated devices by bus name, for tests and benchmarks (unplug, packet logs).
        self.sabertooth: dict[str, Any] = {}
        self.odrive: dict[str, Any] = {}
        self._watched: dict[str, int] = {}
        #: Buses the `sim` module has unplugged.
        self.unplugged: set[str] = set()
        self.sim_module: Any = None  # the `sim` module, made by `attach`

    def bus_factory(self, bc: BusConfig) -> Bus:
        if not bc.sim:
            log.info("bus %s keeps its real %s driver (sim: false)", bc.name, bc.driver)
            return default_bus_factory(bc)
        if self.wire_level:
            bus = self._wire_level(bc)
            if bus is not None:
                return bus
        return SimBus(bc.name, dict(bc.params), world=self.signals)

    def _wire_level(self, bc: BusConfig) -> Bus | None:
        """A real driver talking to an emulator, where one exists for this driver."""
        if bc.driver == "sabertooth":
            return self._sabertooth(bc)
        if bc.driver == "can":
            return self._odrive(bc)
        return None

    def _motor_labels(self, bus: str, key: str) -> dict[Any, str]:
        """Channel key value (address/motor pair, node id) -> `module.device` on that bus."""
        out: dict[Any, str] = {}
        for mname, mc in self.config.modules.items():
            for dname, dc in mc.devices.items():
                if dc.bus == bus and dc.kind == "motor":
                    ident = (dc.channel["address"], dc.channel["motor"]) if key == "address" \
                        else dc.channel[key]
                    out[ident] = f"{mname}.{dname}"
        return out

    def _sabertooth(self, bc: BusConfig) -> Bus:
        """The Sabertooth firmware emulator behind a pty; the real driver opens its path."""
        from firmware_like.pty_link import PtyLink
        from firmware_like.sabertooth import SabertoothEmulator, SabertoothPtyDevice
        from ramp.hal.sabertooth import SabertoothBus

        labels = self._motor_labels(bc.name, "address")
        world = self.signals

        def on_motor(address: int, motor: int, duty: float) -> None:
            label = labels.get((address, motor))
            if label is not None:
                world.set_motor(label, duty)

        addresses = sorted({a for a, _ in labels}) or [128]
        link = PtyLink(bc.name, self.dir)
        emulator = SabertoothEmulator(addresses, on_motor=on_motor, baud=bc.params["baud"],
                                      paced=True)
        device = SabertoothPtyDevice(link, emulator)
        self.devices.append(link)
        self.sabertooth[bc.name] = device
        params = {**bc.params, "port": link.path}
        log.info("bus %s: Sabertooth emulator (addresses %s) on %s", bc.name,
                 ",".join(map(str, addresses)), link.path)
        return SabertoothBus(bc.name, params)

    def _odrive(self, bc: BusConfig) -> Bus:
        """ODrive emulators on python-can's virtual bus; the real driver talks CAN frames."""
        from firmware_like.odrive import ODriveEmulator
        from ramp.hal.odrive import ODriveBus

        labels = self._motor_labels(bc.name, "node_id")
        max_vel = float(bc.params["max_vel"])
        world = self.signals

        def on_velocity(node: int, turns_per_s: float) -> None:
            label = labels.get(node)
            if label is not None:
                world.set_motor(label, max(-1.0, min(1.0, turns_per_s / max_vel)))

        channel = f"ramp-sim-{id(self):x}-{bc.name}"
        emulator = ODriveEmulator(channel, sorted(labels), on_velocity=on_velocity)
        self.devices.append(emulator)
        self.services.append(emulator.tick)
        self.odrive[bc.name] = emulator
        params = {**bc.params, "interface": "virtual", "channel": channel}
        log.info("bus %s: ODrive emulators (nodes %s) on virtual CAN", bc.name,
                 ",".join(map(str, sorted(labels))))
        return ODriveBus(bc.name, params)

    def attach(self, sup: Supervisor) -> None:
        """Step the world (and service emulators) first in every tick; emulators behind a pty
        also read in the scheduler's I/O wait, so bytes are stamped when they arrive. The
        `sim` module (SPEC 12) joins the robot's requests."""
        from ramp.simulation.sim_module import SimModule

        self._scheduler = sup.scheduler
        self._clock = sup.clock
        sup.scheduler.add_task("sim.world", sup.scheduler.rate_hz, self.tick)
        self.sim_module = SimModule(self)
        sup.robot.add_extra(self.sim_module)

    # -- the `sim` module's hooks (SPEC 12) ---------------------------------------------------
    def unplug(self, bus: str) -> None:
        """The bus's emulated device vanishes the way real hardware does: a Sabertooth's pty
        closes (the driver sees the cable pulled), the ODrive axes fall silent on the CAN
        bus, a HAL-level sim board reports itself gone. The real hot-plug path notices."""
        if bus in self.sabertooth:
            self.sabertooth[bus].link.unplug()
        elif bus in self.odrive:
            self.odrive[bus].silence()
        else:
            self.world.unplug(bus)
        self.unplugged.add(bus)

    def plug(self, bus: str) -> None:
        """The device comes back; the driver's retry (hot plug) finds it again."""
        if bus in self.sabertooth:
            link = self.sabertooth[bus].link
            if not link.plugged:
                link.replug()
        elif bus in self.odrive:
            self.odrive[bus].resume()
        else:
            self.world.replug(bus)
        self.unplugged.discard(bus)

    def tick(self, now: float, dt: float) -> None:
        self._watch_ptys()
        unread = [d for name, d in self.sabertooth.items() if name not in self._watched]
        if unread:  # one look at every pty the wait does not watch, then read those with bytes
            ready = _readable([d.link.fileno() for d in unread])
            for device in unread:
                if device.link.fileno() in ready:
                    device.service(now)
                else:
                    device.emulator.tick(now)
        for name, device in self.sabertooth.items():
            if name in self._watched:
                device.emulator.tick(now)  # its bytes are read when the pty is readable
        for service in self.services:
            service(now)
        self._physics_dt += dt
        if self.physics_hz is None or self._physics_dt * self.physics_hz >= 1.0 - 1e-6:
            self.world.step(self._physics_dt)
            self._physics_dt = 0.0

    def _watch_ptys(self) -> None:
        """(Re)register each pty master with the loop: a replug opens a new one."""
        sched = getattr(self, "_scheduler", None)
        if sched is None or not self.read_in_wait:
            return
        for name, device in self.sabertooth.items():
            fd = device.link.master_fd
            old = self._watched.get(name)
            if old == fd:
                continue
            if old is not None:
                sched.remove_reader(old)
            if fd >= 0:
                sched.add_reader(fd, lambda d=device: d.service(self._clock.now()))
                self._watched[name] = fd
            else:
                self._watched.pop(name, None)

    def close(self) -> None:
        for dev in self.devices:
            close = getattr(dev, "close", None)
            if close is not None:
                close()
        self._tmp.cleanup()
