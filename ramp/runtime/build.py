"""`build(config, clock, bus_factory)`: the one place a robot is assembled from its config.

`ramp run`, `ramp run --sim`, `ramp sim …` (the simulation rig), the tests' harness and the
benchmarks all build their supervisor here; they differ only in the clock, the bus factory
(real drivers, or `ramp.simulation.backplane`'s emulators) and an optional `Observer`. The
config is data (`ramp.config`); everything that runs is made here, bottom up: buses and
their channels (HAL), modules on those channels (functional and module distribution
layers), the module registry, the watchdog and the robot layer, then the server.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ramp.clock import Clock, MonotonicClock
from ramp.config import BusConfig, Config
from ramp.config.access import check_exposure, is_loopback, server_context
from ramp.errors import ConfigError, DeviceError, RampError
from ramp.hal import driver_class
from ramp.hal.interfaces import Bus
from ramp.layers.module_distribution import BoundDevice, Module
from ramp.layers.robot_distribution import (
    Health,
    Interlocks,
    ModuleRegistry,
    ModuleSlot,
    RobotDistribution,
    Watchdog,
)
from ramp.layers.server import McpServer
from ramp.modules import module_class
from ramp.registry import origin
from ramp.registry import where as _where
from ramp.runtime.buses import BusManager, zeroer
from ramp.runtime.observers import Observer, fan_out, overridden
from ramp.runtime.supervisor import Supervisor
from ramp.scheduler import Scheduler

if TYPE_CHECKING:
    from ramp.recorder.recorder import Recorder

BusFactory = Callable[[BusConfig], Bus]

log = logging.getLogger("ramp.supervisor")


def default_bus_factory(bc: BusConfig) -> Bus:
    """The real driver named in YAML."""
    return driver_class(bc.driver)(bc.name, bc.params)


#: The tick rate while nothing moves (`scheduler.idle_rate_hz`) when the file sets none, on
#: the wall clock. A virtual clock spends no wall time waiting, so there it ticks at the base
#: rate unless the file asks: simulated runs and tests keep their exact sampling.
IDLE_RATE_HZ = 20.0


def idle_rate(config: Config, clock: Clock) -> float | None:
    """The tick rate while nothing moves (None: every base period). Not on a robot with an
    interlock rule that stops or latches: such a rule is a safety event (a bumper), and what
    it reads is sampled and debounced by tasks at their own rate; at the idle rate a short
    press could fall between two samples and never latch, and a held one would take several
    idle ticks."""
    hz = config.idle_rate_hz
    if hz is None and not clock.virtual:
        hz = IDLE_RATE_HZ
    events = [r.name for r in config.interlocks if r.latch or r.action == "stop"]
    if hz is not None and config.rate_hz / hz >= 2 - 1e-9 and events:  # a stride of 2+
        log.info("idle ticks off: the loop ticks at %g Hz at rest too, for the interlock "
                 "rules that stop or latch (%s)", config.rate_hz, ", ".join(events))
        return None
    return hz


def build(config: Config, clock: Clock | None = None, bus_factory: BusFactory | None = None,
          *, host: str | None = None, port: int | None = None,
          observer: Observer | None = None, recorder: Recorder | None = None) -> Supervisor:
    """A supervisor for `config`, not started yet (`start()`, then `settle()`, then run its
    scheduler). `host`/`port` override the config's server address (`--host`, `--port`).
    `recorder` (not started yet; `ramp.runtime.recording.recorder_for`) records the run:
    the supervisor starts it, feeds it through the observer points beside `observer`, and
    closes it at shutdown.
    Raises ConfigError for what only building can find (two devices on one channel ...)."""
    clock = clock or MonotonicClock()
    scheduler = Scheduler(clock, config.rate_hz, stall_limit=config.stall_limit,
                          idle_rate_hz=idle_rate(config, clock))
    factory = bus_factory or default_bus_factory
    buses: dict[str, Bus] = {}
    for name, bc in config.buses.items():
        buses[name] = _bus(bc, factory)

    slots: dict[str, ModuleSlot] = {}
    for name, mc in config.modules.items():
        used = tuple(sorted({dc.bus for dc in mc.devices.values()}))
        broken = mc.broken or "; ".join(
            f"bus {b}: {bus.reason}" for b in used
            if isinstance(bus := buses[b], UnloadedBus))
        module: Module | None = None
        channels: list[object] = []
        if not broken:
            try:
                devices = {
                    dev: BoundDevice(buses[dc.bus].channel(dc.kind, f"{name}.{dev}",
                                                           dc.channel), dc.params)
                    for dev, dc in mc.devices.items()
                }
                module = module_class(mc.type)(name, devices, mc.settings)
                channels = [d.channel for d in devices.values()]
            except RampError:  # a config mistake the module found: a refusal, as always
                raise
            except Exception as exc:  # noqa: BLE001 - plugin code: this module's fault only
                broken = (f"{origin('ramp.modules', mc.type)} raised when built: "
                          f"{_where(exc)}{type(exc).__name__}: {exc}")
                log.error("module %s: its module type's code raised when built; the rest of "
                          "the robot starts without it", name, exc_info=exc)
        slot = slots[name] = ModuleSlot(name, module or Unloaded(name), used)
        slot.plugin = origin("ramp.modules", mc.type)
        slot.zero = zeroer(channels)
        if module is None:
            log.error("module %s is in fault for good (fix the plugin and restart): %s",
                      name, broken)
            slot.retry_at = math.inf  # never attached: its code is not there
            slot.fail(0.0, broken)
    registry = ModuleRegistry(slots)

    # The layers call back into the supervisor, which is made last (it holds them all).
    def health() -> Health:
        return sup.health()

    def buses_changed(now: float) -> None:
        sup.buses_changed(now)

    manager = BusManager(buses, scheduler, buses_changed)
    robot = RobotDistribution(registry, Watchdog(config.watchdog_timeout), health,
                              scheduler.stats, Interlocks(config.interlocks, slots))
    serve_on = host if host is not None else config.server.host
    problem = check_exposure(serve_on, config.server.tls, config.access)
    if problem is not None:  # `--host 0.0.0.0` on a file without TLS (SPEC 13)
        raise ConfigError(problem, file=config.file, key="server.host",
                          line=config.lines.get("server.host", 0))
    tls = server_context(config.server.tls) if config.server.tls is not None else None
    if config.access.allow_anonymous and not is_loopback(serve_on):
        robot.access_mode = "anonymous"
        logging.getLogger("ramp.access").warning(
            "MCP on %s with NO authentication (access.allow_anonymous: true): anyone who "
            "can reach this address may drive the robot; set up server.tls "
            "(docs/operating/security.md)", serve_on)
    server = McpServer(scheduler, robot, host=serve_on,
                       port=port if port is not None else config.server.port,
                       max_clients=config.server.max_clients, max_line=config.server.max_line,
                       max_output=config.server.max_output, tls=tls, access=config.access)
    if recorder is not None:
        from ramp.runtime.recording import RecorderObserver

        outputs = [ch.label for bus in buses.values() for ch in bus.outputs]
        observer = fan_out(RecorderObserver(recorder, outputs), observer)
    sup = Supervisor(config, clock, scheduler, manager, registry, robot, server, observer,
                     recorder)
    scheduler.on_stall = sup.on_stall
    if observer is not None:
        _connect(sup, observer)
    return sup


class Unloaded(Module):
    """What stands in for a module whose plugin could not be loaded or built: no devices,
    nothing to move, in `fault` for good (its requests answer `fault` with the reason)."""

    def stop(self) -> None:
        pass

    def is_moving(self) -> bool:
        return False


class UnloadedBus(Bus):
    """What stands in for a bus whose driver could not be loaded or built: it never opens
    (every retry says why), and the modules on it are in `fault` for good."""

    driver_name = "unloaded"

    def __init__(self, name: str, reason: str) -> None:
        super().__init__(name, {})
        self.reason = reason

    def _make_channel(self, kind: str, label: str, spec: dict[str, Any]) -> Any:
        raise ConfigError(f"bus {self.name} has no driver: {self.reason}", key=label)

    def _open(self, now: float) -> None:
        raise DeviceError(self.name, self.reason)

    def _tick(self, now: float, dt: float) -> None:
        pass

    def _stop_motors(self) -> None:
        pass

    def _close(self) -> None:
        pass


def _bus(bc: BusConfig, factory: BusFactory) -> Bus:
    """Bus `bc` built by `factory`; a driver whose code cannot be loaded, or raises when
    built, is an `UnloadedBus` (SPEC 2.2: the rest of the robot starts), reported by its
    distribution and entry point."""
    if bc.broken:
        log.error("bus %s: %s; the rest of the robot starts without it", bc.name, bc.broken)
        return UnloadedBus(bc.name, bc.broken)
    try:
        return factory(bc)
    except RampError:  # a config mistake the driver found (or the sim driver off --sim)
        raise
    except Exception as exc:  # noqa: BLE001 - plugin code: this bus's fault only
        reason = (f"{origin('ramp.drivers', bc.driver)} raised when built: {_where(exc)}"
                  f"{type(exc).__name__}: {exc}")
        log.error("bus %s: its driver's code raised when built; the rest of the robot starts "
                  "without it", bc.name, exc_info=exc)
        return UnloadedBus(bc.name, reason)


def _connect(sup: Supervisor, observer: Observer) -> None:
    """Connect the observer's overridden points to the layers' hooks (see
    `ramp.runtime.observers`); the others stay None and cost nothing."""
    now = sup.clock.now
    if overridden(observer, "message_in"):
        sup.server.on_message_in = lambda client, t, msg: observer.message_in(t, client, msg)
    if overridden(observer, "message_out"):
        sup.server.on_message_out = lambda client, t, line: observer.message_out(t, client, line)
    if overridden(observer, "command"):
        for name, bus in sup.buses.items():
            bus.on_command = (lambda bus_name: lambda channel, value: observer.command(
                now(), bus_name, channel, value))(name)
    if overridden(observer, "module_state"):
        for slot in sup.slots.values():
            slot.on_change = lambda module, state, reason, t: observer.module_state(
                t, module, state, reason)
    if overridden(observer, "watchdog"):
        sup.watchdog.on_change = lambda state, why, t: observer.watchdog(t, state, why)
    if overridden(observer, "audit"):
        sup.robot.on_audit = lambda client, req, outcome, t: observer.audit(
            t, client, req, outcome)
    if overridden(observer, "interlock"):
        sup.robot.interlocks.on_change = lambda name, active, why, t: observer.interlock(
            t, name, active, why)
    if overridden(observer, "control"):
        sup.robot.on_control = lambda owner, peer, t: observer.control(t, owner, peer)
    if overridden(observer, "bus_fault"):
        sup.bus_manager.on_fault = lambda bus, reason, t: observer.bus_fault(t, bus, reason)
    if overridden(observer, "tick"):
        sup.scheduler.on_tick = observer.tick
    if overridden(observer, "tick_done"):
        sup.scheduler.on_tick_done = observer.tick_done
