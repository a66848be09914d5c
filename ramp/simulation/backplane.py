"""The one simulation entry point: wires emulators and physics to real drivers, from the
`ramp.emulators` entry points, with no branch per driver or module.

`ramp run --sim` replaces every bus, except those marked `sim: false`, by its emulator:
a driver with a `bus.DRIVER` emulator (RAMP's: `sabertooth`, a firmware emulator behind a pty;
`can`, ODrive emulators on python-can's virtual bus) keeps its real driver, opened on the
emulator's port; any other bus becomes the HAL-level sim driver (USB boards such as Phidgets
cannot be emulated at the wire). Both move one `World` (`firmware_like.world`) made of parts:
each module type's `module.TYPE` emulator adds the physics of that module (MARTE's `base` and
`ble` share one coupled model; Scout's `diff_base` a chassis on a flat floor; a plugin's arm
its joints), stepped by a scheduler task on the supervisor's clock.

A module type with no emulator still runs: its signals are simulated plainly (motors and
outputs recorded, inputs read 0), so a new robot's wiring can be tried under --sim before it
has a physics model.
"""

from __future__ import annotations

import logging
import select
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from firmware_like.world import World
from ramp.config import BusConfig, Config
from ramp.hal import driver_class
from ramp.hal.interfaces import Bus
from ramp.hal.simio import SimBus
from ramp.registry import emulators
from ramp.runtime import default_bus_factory

if TYPE_CHECKING:
    from ramp.runtime.supervisor import Supervisor

log = logging.getLogger("ramp.sim")

T = TypeVar("T")

#: How often `ramp run --sim` steps the physics (s^-1). One step of the MARTE model costs
#: about as much as the rest of a tick together, and its longest piece is 0.05 s
#: (`MarteParams.max_step`), so 20 Hz is one piece per step: the supervisor's own ticks stay
#: cheap and the model its own. The emulated devices (paced wire, serial timeouts) are
#: serviced every tick regardless. `ramp sim …` and the tests step it every tick.
RUN_PHYSICS_HZ = 20.0


class SimBackplane:
    """Builds the simulated world and the bus for each config entry; it is the
    `EmulatorContext` (`ramp.api`) the emulators are built with."""

    def __init__(self, config: Config, world: Any = None,
                 wire_level: bool = True, physics_hz: float | None = None,
                 read_in_wait: bool = True) -> None:
        """`world`: a model to use for the modules whose emulator asks for it by the key
        "marte" (the simulation rig hands in its seeded `MarteWorld`); None builds what the
        emulators make. `physics_hz`: how often the world is stepped (None: every tick, the
        default, so a simulated run is the same at any tick rate); the emulated devices are
        serviced every tick whatever it is, so their serial timeouts stay exact.

        `read_in_wait`: an emulator behind a pty reads the driver's bytes the moment they
        arrive (the loop's wait watches the pty), as the tests and `ramp sim` want; False
        reads them once per tick instead, for `ramp run --sim` on the wall clock, where a pty
        in the loop's wait is polled by the kernel at every request the supervisor answers
        (about 1 µs each, 5 % of a round trip) to save the emulators a few milliseconds."""
        self.config = config
        self.physics_hz = physics_hz
        self.read_in_wait = read_in_wait
        self._physics_dt = 0.0
        self.wire_level = wire_level
        self.devices: list[Any] = []  # emulated devices closed with the backplane
        self._tmp = tempfile.TemporaryDirectory(prefix="ramp-sim-")
        self.dir = Path(self._tmp.name)
        self.services: list[Callable[[float], Any]] = []
        #: Emulated devices behind a pty, by bus name (tests and benchmarks: unplug, logs).
        self.sabertooth: dict[str, Any] = {}
        #: Every bus emulator by bus name, as its `bus.DRIVER` entry returned it.
        self.emulated: dict[str, Any] = {}
        self.odrive = self.emulated  # the name the tests of the CAN emulators use
        self._watched: dict[str, int] = {}
        self._poller = select.poll()  # the ptys the loop's wait does not watch (`tick`)
        self._polled_fds: list[int] = []
        self._scheduler: Any = None  # the supervisor's, once attached
        #: Buses the `sim` module has unplugged.
        self.unplugged: set[str] = set()
        self.sim_module: Any = None  # the `sim` module, made by `attach`
        self._shared: dict[str, Any] = {}
        if world is not None:
            self._shared["marte"] = world
        #: The signals buses and emulators drive: the parts' and plain ones for the rest.
        self.signals = World([world] if world is not None else [])
        #: (part, module) for each module whose emulator made that part.
        self._part_modules: list[tuple[Any, str]] = []
        #: Buses whose emulator part faulted: dead for good (`plug` leaves them unplugged).
        self.dead: set[str] = set()
        for name, mc in config.modules.items():
            key = f"module.{mc.type}"
            if key in emulators():
                try:
                    part = emulators().load(key)(self, name, mc)
                except Exception:  # noqa: BLE001 - plugin code: that module's buses, not the run
                    log.exception("sim: the %s emulator (ramp.emulators entry %s) of module %s "
                                  "failed to load or build; its buses start dead, the rest "
                                  "of the world runs", mc.type, key, name)
                    self.dead.update(dc.bus for dc in mc.devices.values() if dc.bus)
                    continue
                if part is not None:
                    self.signals.add(part)
                    self._part_modules.append((part, name))
        self.signals.on_part_fault = self._part_faulted
        #: The model the tests and the rig inspect: MARTE's when there is one, else the world.
        self.world = self._shared.get("marte", self.signals)

    # -- EmulatorContext --------------------------------------------------------------------
    def shared(self, key: str, make: Callable[[], T]) -> T:
        """One object per key for the whole world: the parts that share a model or a floor."""
        if key not in self._shared:
            self._shared[key] = make()
        out: T = self._shared[key]
        return out

    def add_device(self, device: Any) -> None:
        """Closed (its `close()`) when the simulation ends."""
        self.devices.append(device)

    def add_service(self, service: Callable[[float], Any]) -> None:
        """Called with the time at every tick, before the physics steps."""
        self.services.append(service)

    def add_pty_device(self, bus: str, device: Any) -> None:
        """A device behind a pty (`device.link` a `PtyLink`, `device.service(now)` reads the
        driver's bytes, `device.emulator.tick(now)` its timers): read as bytes arrive."""
        self.devices.append(device.link)
        self.sabertooth[bus] = device

    def add_bus_emulator(self, bus: str, emulator: Any) -> None:
        """The emulator behind `bus`, by name (the `sim` module's unplug, tests)."""
        self.emulated[bus] = emulator

    def motor_labels(self, bus: str, *keys: str) -> dict[Any, str]:
        """Channel key values (one key: its value; several: a tuple) -> `module.device`, for
        the motors wired to `bus`."""
        out: dict[Any, str] = {}
        for mname, mc in self.config.modules.items():
            for dname, dc in mc.devices.items():
                if dc.bus == bus and dc.kind == "motor":
                    vals = tuple(dc.channel[k] for k in keys)
                    out[vals[0] if len(vals) == 1 else vals] = f"{mname}.{dname}"
        return out

    # -- buses ------------------------------------------------------------------------------
    def bus_factory(self, bc: BusConfig) -> Bus:
        if not bc.sim:
            log.info("bus %s keeps its real %s driver (sim: false)", bc.name, bc.driver)
            return default_bus_factory(bc)
        bus = self._bus(bc)
        if bc.name in self.dead:  # its module's emulator failed at start: as if unplugged
            self._kill(bc.name)
        return bus

    def _bus(self, bc: BusConfig) -> Bus:
        key = f"bus.{bc.driver}"
        if self.wire_level and key in emulators():
            params = emulators().load(key)(self, bc)
            return driver_class(bc.driver)(bc.name, {**bc.params, **params})
        if self.wire_level and bc.driver != "sim":
            # Said at start, loudly: the driver's own code is not what runs under --sim.
            log.warning("bus %s: driver %s has no emulator (no bus.%s in ramp.emulators): "
                        "--sim replaces it by the HAL-level sim driver, so the %s driver's "
                        "own code is not exercised", bc.name, bc.driver, bc.driver, bc.driver)
        return SimBus(bc.name, dict(bc.params), world=self.signals)

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
        """The bus's emulated device vanishes the way real hardware does: a device behind a
        pty has its pty closed (the driver sees the cable pulled), an emulator with `silence`
        (the ODrive axes) falls silent on its bus, a HAL-level sim board reports itself gone.
        The real hot-plug path notices."""
        if bus in self.sabertooth:
            self.sabertooth[bus].link.unplug()
        elif hasattr(self.emulated.get(bus), "silence"):
            self.emulated[bus].silence()
        else:
            self.signals.unplug(bus)
        self.unplugged.add(bus)

    def _part_faulted(self, part: Any) -> None:
        """An emulator part raised in its step (`World`): every bus wired to a device of the
        modules it simulates goes dead the way unplugged hardware does (`unplug`), so the
        backend's drivers fault those buses and their modules; the rest keeps running."""
        modules = {m for p, m in self._part_modules if p is part}
        buses = sorted({dc.bus for m in modules for dc in self.config.modules[m].devices.values()
                        if dc.bus})
        for bus in buses:
            self._kill(bus)
        log.error("sim: modules %s: their emulator part faulted; buses %s are dead",
                  ", ".join(sorted(modules)) or "(none)", ", ".join(buses) or "(none)")

    def plug(self, bus: str) -> None:
        """The device comes back; the driver's retry (hot plug) finds it again (not a bus
        whose emulator part faulted: it stays dead)."""
        if bus in self.dead:
            log.warning("sim: bus %s stays unplugged: its emulator part faulted", bus)
            return
        if bus in self.sabertooth:
            link = self.sabertooth[bus].link
            if not link.plugged:
                link.replug()
        elif hasattr(self.emulated.get(bus), "resume"):
            self.emulated[bus].resume()
        else:
            self.signals.replug(bus)
        self.unplugged.discard(bus)

    def tick(self, now: float, dt: float) -> None:
        self._watch_ptys()
        watched = self._watched
        # One look at every pty the loop's wait does not watch (none in `ramp sim`, whose wait
        # watches them all): those with bytes are read; the others only run their timers
        # (a watched pty's bytes are read the moment it is readable, `_serve`).
        ready = self._readable_unwatched() if len(watched) < len(self.sabertooth) else ()
        for name, device in self.sabertooth.items():
            if name in self.dead:
                continue
            try:
                if name not in watched and device.link.master_fd in ready:
                    device.service(now)
                else:
                    device.emulator.tick(now)
            except Exception as exc:  # noqa: BLE001 - emulator code: its own bus's fault
                self._device_faulted(name, exc)
        for service in self.services:
            try:
                service(now)
            except Exception:  # noqa: BLE001 - emulator code: that service stops, once
                log.exception("sim: the emulator service %r raised; it is not called again",
                              service)
                self.services.remove(service)
                break  # the list changed: the others run at the next tick
        self._physics_dt += dt
        if self.physics_hz is None or self._physics_dt * self.physics_hz >= 1.0 - 1e-6:
            self.signals.step(self._physics_dt)
            self._physics_dt = 0.0

    def _device_faulted(self, bus: str, exc: Exception) -> None:
        """An emulator behind a pty raised (reading its wire or in its timers): that device
        goes dead the way unplugged hardware does, once, and the backend's driver faults the
        bus; the rest of the world keeps running."""
        log.error("sim: the emulator of bus %s raised; the bus is dead (unplugged for good)",
                  bus, exc_info=exc)
        self._kill(bus)

    def _kill(self, bus: str) -> None:
        """`bus` unplugged for good: `plug` leaves it dead."""
        self.dead.add(bus)
        if bus not in self.unplugged:
            self.unplug(bus)

    def _serve(self, bus: str, device: Any) -> None:
        """A pty with bytes (the loop's wait): the device reads them, guarded."""
        if bus in self.dead:
            return
        try:
            device.service(self._clock.now())
        except Exception as exc:  # noqa: BLE001 - emulator code: its own bus's fault
            self._device_faulted(bus, exc)

    def _readable_unwatched(self) -> set[int] | tuple[()]:
        """Which ptys the loop's wait does not watch have input now: one `poll(0)` on a poller
        kept while their descriptors stay the same (a replug makes a new one), about half
        what a `select` over the same descriptors costs each tick."""
        fds = [d.link.master_fd for name, d in self.sabertooth.items()
               if name not in self._watched and d.link.master_fd >= 0]
        if fds != self._polled_fds:
            self._poller = select.poll()
            for fd in fds:
                self._poller.register(fd, select.POLLIN)
            self._polled_fds = fds
        if not fds:
            return ()
        return {fd for fd, _ in self._poller.poll(0)}

    def service_wire(self, now: float) -> None:
        """Every emulated device reads what its wire carried, once, with no physics step
        (after `Supervisor.shutdown`, whose zeros reach the emulators at the wire's pace)."""
        for device in self.sabertooth.values():
            device.service(now)
            device.emulator.tick(now)
        for service in self.services:
            service(now)

    def _watch_ptys(self) -> None:
        """(Re)register each pty master with the loop: a replug opens a new one."""
        sched = self._scheduler
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
                sched.add_reader(fd, lambda b=name, d=device: self._serve(b, d))
                self._watched[name] = fd
            else:
                self._watched.pop(name, None)

    def close(self) -> None:
        for dev in self.devices:
            close = getattr(dev, "close", None)
            if close is not None:
                close()
        self._tmp.cleanup()
