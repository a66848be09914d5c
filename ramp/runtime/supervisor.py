"""The Supervisor: builds every layer from a Config and runs them on one scheduler.

One object owns everything (no singletons), so each test builds a fresh one. It also keeps
the module/bus attachment state: a bus that fails faults its modules and stops their motion;
a closed bus is retried about once a second and its modules re-attach when it is back.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from ramp.clock import Clock, MonotonicClock
from ramp.config import BusConfig, Config
from ramp.errors import DeviceError
from ramp.hal import driver_class
from ramp.hal.interfaces import Bus
from ramp.layers.module_distribution import BoundDevice, Module
from ramp.layers.robot_distribution import Health, ModuleSlot, RobotDistribution
from ramp.layers.robot_distribution.watchdog import Watchdog
from ramp.layers.server import Connection, McpServer
from ramp.mcp.messages import Response
from ramp.mcp.protocol import TooLong, parse_message, too_long_response
from ramp.modules import module_class
from ramp.runtime.bus_opener import BusOpener
from ramp.runtime.stall_guard import StallGuard
from ramp.scheduler import Scheduler

log = logging.getLogger("ramp.supervisor")

BusFactory = Callable[[BusConfig], Bus]
RETRY_PERIOD = 1.0  # seconds between attempts to reopen a missing device


def default_bus_factory(bc: BusConfig) -> Bus:
    return driver_class(bc.driver)(bc.name, bc.params)


@dataclass
class BusHealth:
    """Why a bus is closed, and when to try it again."""

    reason: str = "not opened yet"
    next_retry: float = 0.0
    faults: int = 0


class Supervisor:
    def __init__(self, config: Config, clock: Clock | None = None, *,
                 bus_factory: BusFactory | None = None, host: str | None = None,
                 port: int | None = None) -> None:
        self.config = config
        self.clock = clock or MonotonicClock()
        self.scheduler = Scheduler(self.clock, config.rate_hz, stall_limit=config.stall_limit)
        self.scheduler.on_stall = self._on_stall
        factory = bus_factory or default_bus_factory
        self.buses: dict[str, Bus] = {name: factory(bc) for name, bc in config.buses.items()}
        for bus in self.buses.values():
            bus.gate = self.scheduler.on_time  # motion computed before a stall never goes out
        self.bus_health = {name: BusHealth() for name in self.buses}
        self.opener = BusOpener(inline=self.clock.virtual)
        slots: dict[str, ModuleSlot] = {}
        for name, mc in config.modules.items():
            devices = {
                dev: BoundDevice(
                    self.buses[dc.bus].channel(dc.kind, f"{name}.{dev}", dc.channel), dc.params)
                for dev, dc in mc.devices.items()
            }
            module: Module = module_class(mc.type)(name, devices, mc.settings)
            used = tuple(sorted({dc.bus for dc in mc.devices.values()}))
            slots[name] = ModuleSlot(name, module, used)
        self.slots = slots
        self.watchdog = Watchdog(config.watchdog_timeout)
        self.robot = RobotDistribution(slots, self.watchdog, self._health)
        self.robot.on_device_error = self._request_hit_fault
        self.server = McpServer(
            self.scheduler, self._handle, self.robot.client_lost,
            host=host if host is not None else config.server.host,
            port=port if port is not None else config.server.port,
            max_clients=config.server.max_clients, max_line=config.server.max_line,
            max_output=config.server.max_output, protected=self.robot.protects)
        # max_line already bounds a message's work; every well-formed one fits (>= 8 bytes each)
        self._max_requests = max(256, config.server.max_line // 8 + 1)
        self.stall_guard = StallGuard(self, config.stall_limit)
        self.started_at = 0.0
        self.running = False

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self) -> None:
        """Open every bus (missing ones are retried later), attach modules, start serving."""
        now = self.clock.now()
        self.started_at = now
        for name, bus in self.buses.items():  # in parallel: each open has its own thread
            self._try_open(name, bus, now, quiet=True)
        for name, bus in self.buses.items():
            if self.opener.busy(name):
                self._try_open(name, bus, now)
        self._update_slots(now)
        sched = self.scheduler
        sched.add_task("buses", sched.rate_hz, self._tick_buses)
        sched.add_task("watchdog", sched.rate_hz, self.robot.tick)
        sched.add_task("hotplug", self._divisor_rate(1.0), self._retry_buses)
        for slot in self.slots.values():
            for task in slot.module.tasks():
                rate = self._divisor_rate(task.rate_hz)
                if abs(rate - task.rate_hz) > 1e-9:
                    log.info("task %s.%s runs at %g Hz (asked %g Hz; base rate %g Hz)",
                             slot.name, task.name, rate, task.rate_hz, sched.rate_hz)
                sched.add_task(f"{slot.name}.{task.name}", rate,
                               self._only_attached(slot, task.run))
        self.server.start()
        self.running = True

    def settle(self, limit: float = 2.0, open_limit: float = 0.5) -> None:
        """Run the loop (serving) until every opened bus reports ready, at most `limit` s.

        Boards such as ODrives and Phidgets open at once but answer a moment later; the ready
        line waits for them so a client connecting right after sees its modules attached.
        An open still running after `open_limit` (a device that does not answer) is not
        waited for: its modules attach when it is done.
        """
        start = self.clock.now()
        end = start + limit

        def settled() -> bool:
            now = self.clock.now()
            opening = self.opener.in_flight and now < start + open_limit
            return now >= end or (not opening and all(
                b.ready() for b in self.buses.values() if b.is_open))

        self.scheduler.run(settled)

    def shutdown(self) -> None:
        """Stop every motor (zeros on the wire), close devices and the server. Idempotent."""
        if not self.running and not any(b.is_open for b in self.buses.values()):
            return
        self.running = False
        self.robot.stop_all("shutdown")
        self.opener.cancel_all()
        for bus in self.buses.values():
            bus.close()  # zeros on the wire first, then the port closes
        self.server.close()

    def stop_all_motors(self, alive_mark: float, lock_wait: float = 0.02) -> None:
        """Last resort (the stall guard's thread, the loop silent since `alive_mark`): zeros
        straight to every driver the loop is not inside (see the bus lock in
        `ramp.hal.interfaces`). The loop, when it runs again, treats this as a stall, so
        the layers above agree with the wire."""
        self.scheduler.request_stall_stop(alive_mark)
        for name, bus in self.buses.items():
            try:
                if not bus.try_stop_motors(lock_wait):
                    log.error("bus %s: the tick loop is stuck inside its driver; its motors "
                              "are left to the controller's own timeout", name)
            except Exception as exc:  # noqa: BLE001 - every other bus must still stop
                log.error("bus %s: could not stop motors: %s", name, exc)

    def _zeros_everywhere(self) -> None:
        for name, bus in self.buses.items():
            if not bus.is_open:
                continue
            try:
                bus.stop_motors()
            except Exception as exc:  # noqa: BLE001 - every other bus must still stop
                log.error("bus %s: could not stop motors: %s", name, exc)

    def _on_stall(self, gap: float, unit: str) -> None:
        """The loop lost more than `stall_limit` (SPEC 2.2). Before anything else goes out:
        zeros on every wire, which also turns every queued command and every refresh value
        into a zero; then every module stops and the watchdog trips."""
        self._zeros_everywhere()
        self.robot.stalled("tick loop stalled")
        self.stall_guard.loop_stalled(gap, unit)

    def _divisor_rate(self, wanted_hz: float) -> float:
        """The rate nearest `wanted_hz` that divides the base rate (at most the base rate)."""
        divisor = max(1, round(self.scheduler.rate_hz / wanted_hz))
        return self.scheduler.rate_hz / divisor

    # -- requests -----------------------------------------------------------------------------
    def _handle(self, conn: Connection, msg: bytes | TooLong) -> Iterator[list[Response]]:
        """One message's answer, one request per step (the server stops between steps when
        the tick is due). Nothing runs before the first step."""
        now = self.clock.now()
        if isinstance(msg, TooLong):
            self.robot.feed(conn, now)
            yield [too_long_response(self.config.server.max_line)]
            return
        parsed = parse_message(msg, max_requests=self._max_requests)
        yield from self.robot.handle_steps(conn, parsed.requests, now, parsed.syntax_error)

    def _health(self) -> Health:
        s = self.scheduler.stats
        return Health(uptime=self.clock.now() - self.started_at, rate_hz=self.scheduler.rate_hz,
                      late_us=s.percentiles(), overruns=s.overruns,
                      clients=len(self.server.clients))

    # -- buses and attachment -----------------------------------------------------------------
    def _try_open(self, name: str, bus: Bus, now: float, quiet: bool = False) -> bool:
        """Open a bus without holding the loop (see `ramp.runtime.bus_opener`); True once it
        is open. A failure waits RETRY_PERIOD before the next try; an open still running is
        looked at again on the next tick. `quiet`: start it and do not wait (the others start
        too)."""
        if quiet and not self.opener.inline:
            self.opener.open(name, bus, now)
            return False
        result = self.opener.open(name, bus, now)
        if result is False:
            return False
        health = self.bus_health[name]
        if isinstance(result, DeviceError):
            if health.reason != result.detail:
                log.warning("bus %s (%s) unavailable: %s; retrying every %.0f s", name,
                            bus.driver_name, result.detail, RETRY_PERIOD)
            health.reason = result.detail
            health.next_retry = now + RETRY_PERIOD
            return False
        health.reason = ""
        log.info("bus %s (%s) open", name, bus.driver_name)
        return True

    def _tick_buses(self, now: float, dt: float) -> None:
        if self.opener.in_flight:
            self._collect_opens(now)
        for name, bus in self.buses.items():
            if not bus.is_open:
                continue
            try:
                bus.tick(now, dt)
            except DeviceError as exc:
                self._bus_fault(name, exc, now)
        self._update_slots(now)

    def _collect_opens(self, now: float) -> None:
        """Opens that were still running: take their results as soon as they are in."""
        for name, bus in self.buses.items():
            was_down = self.bus_health[name].reason != BusHealth.reason
            if self.opener.busy(name) and self._try_open(name, bus, now) and was_down:
                log.info("bus %s is back", name)

    def _retry_buses(self, now: float, dt: float) -> None:
        reopened = False
        for name, bus in self.buses.items():
            if (not bus.is_open and not self.opener.busy(name)
                    and now >= self.bus_health[name].next_retry
                    and self._try_open(name, bus, now)):
                log.info("bus %s is back", name)
                reopened = True
        if reopened:
            self._update_slots(now)

    def _bus_fault(self, name: str, exc: DeviceError, now: float) -> None:
        health = self.bus_health[name]
        health.faults += 1
        health.reason = exc.detail
        health.next_retry = now + RETRY_PERIOD
        log.error("bus %s fault: %s", name, exc.detail)
        self.buses[name].close()
        self._update_slots(now)

    def _request_hit_fault(self, module: str, exc: DeviceError) -> None:
        if exc.bus in self.buses and self.buses[exc.bus].is_open:
            self._bus_fault(exc.bus, exc, self.clock.now())

    def _update_slots(self, now: float) -> None:
        for slot in self.slots.values():
            ready = all(self.buses[b].ready() for b in slot.buses)
            if ready and slot.state != "ok":
                was = slot.state
                slot.state, slot.reason = "ok", ""
                slot.module.start(now)
                log.info("module %s %s", slot.name,
                         "attached" if was == "detached" else "re-attached")
            elif not ready and slot.state == "ok":
                down = [b for b in slot.buses if not self.buses[b].ready()]
                slot.state = "fault"
                slot.reason = "; ".join(
                    f"bus {b}: {self.bus_health[b].reason or 'not ready'}" for b in down)
                try:
                    slot.module.stop()
                except Exception:
                    log.exception("module %s failed to stop", slot.name)
                log.error("module %s fault: %s; its motion is stopped", slot.name, slot.reason)
            elif not ready and slot.state == "detached":
                down = [b for b in slot.buses if not self.buses[b].ready()]
                slot.reason = "; ".join(
                    f"bus {b}: {self.bus_health[b].reason or 'not ready'}" for b in down)
        if not self.robot.any_moving():
            self.watchdog.disarm()

    @staticmethod
    def _only_attached(slot: ModuleSlot,
                       run: Callable[[float, float], None]) -> Callable[[float, float], None]:
        def task(now: float, dt: float) -> None:
            if slot.state == "ok":
                run(now, dt)
        return task
