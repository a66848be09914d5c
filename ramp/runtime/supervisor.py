"""The Supervisor: every layer of one robot, running on one scheduler.

One object owns everything (no singletons), so each test builds a fresh one; it is built
by `ramp.runtime.build` (the same builder for `ramp run`, `ramp sim`, the tests and the
benchmarks) and owns only the lifecycle and the robot-wide events that cut across the
layers: start and settle, shutdown, a stalled loop, the stall guard's last resort.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from ramp.clock import Clock
from ramp.config import Config
from ramp.hal.interfaces import Bus
from ramp.layers.robot_distribution import (
    Health,
    ModuleRegistry,
    ModuleSlot,
    RobotDistribution,
    Watchdog,
)
from ramp.layers.server import McpServer
from ramp.mcp.messages import Response
from ramp.runtime.buses import BusManager
from ramp.runtime.latch_state import CHECK_HZ, LatchState
from ramp.runtime.observers import Observer
from ramp.runtime.stall_guard import StallGuard
from ramp.scheduler import Scheduler

if TYPE_CHECKING:
    from ramp.recorder.recorder import Recorder

log = logging.getLogger("ramp.supervisor")


class Supervisor:
    """The running robot: scheduler, buses, module registry, robot layer, server."""

    def __init__(self, config: Config, clock: Clock, scheduler: Scheduler,
                 buses: BusManager, registry: ModuleRegistry, robot: RobotDistribution,
                 server: McpServer, observer: Observer | None = None,
                 recorder: Recorder | None = None) -> None:
        self.config = config
        self.clock = clock
        self.scheduler = scheduler
        self.bus_manager = buses
        self.registry = registry
        self.robot = robot
        self.server = server
        self.observer = observer
        #: The flight recorder (`ramp.runtime.recording`), or None when not recording.
        self.recorder = recorder
        self._log_handler: logging.Handler | None = None
        self.stall_guard = StallGuard(self, config.stall_limit)
        #: Latches kept across restarts (`ramp run --state-dir`); None keeps them in memory.
        self.latch_state: LatchState | None = None
        self.started_at = 0.0
        self.running = False

    # -- what tests, tools and observers look at ------------------------------------------------
    @property
    def buses(self) -> dict[str, Bus]:
        return self.bus_manager.buses

    @property
    def slots(self) -> dict[str, ModuleSlot]:
        return self.registry.slots

    @property
    def watchdog(self) -> Watchdog:
        return self.robot.watchdog

    def health_rows(self) -> list[Response]:
        """`robot:robot.get=()`'s rows (what a recorder samples at 10 Hz)."""
        return self.robot.health_rows()

    def module_rows(self, name: str) -> list[Response]:
        """A module's get rows while it is attached, else none."""
        slot = self.slots.get(name)
        if slot is None or slot.state != "ok":
            return []
        return slot.module.rows()

    def health(self) -> Health:
        s = self.scheduler.stats
        rec = self.recorder
        return Health(uptime=self.clock.now() - self.started_at, rate_hz=self.scheduler.rate_hz,
                      late_us=s.percentiles(), overruns=s.overruns,
                      clients=len(self.server.clients),
                      recorder_dropped=rec.dropped if rec is not None else None)

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self) -> None:
        """Open every bus (missing ones are retried later), attach modules, start serving."""
        now = self.clock.now()
        self.started_at = now
        if self.recorder is not None:
            self._start_recorder(now)
        sched = self.scheduler
        if self.latch_state is not None:  # before any bus opens: nothing moves unlatched
            self.latch_state.restore(self.slots, self.robot.interlocks)
            sched.add_task("latches", self._divisor_rate(CHECK_HZ), self.latch_state.check)
        self.bus_manager.start(now)
        sched.add_task("buses", sched.rate_hz, self.bus_manager.tick)
        sched.add_task("watchdog", sched.rate_hz, self.robot.tick)
        interlocks = self.robot.interlocks
        if interlocks.rules:  # after the buses' samples, before any module's work
            sched.add_task("interlocks", sched.rate_hz, interlocks.tick)
            interlocks.tick(now, 0.0)  # what the first client sees is already evaluated
        sched.add_task("hotplug", self._divisor_rate(1.0), self.bus_manager.retry)
        sched.add_task("modules.retry", self._divisor_rate(1.0), self._retry_modules)
        for slot in self.slots.values():
            try:
                tasks = slot.module.tasks()
            except Exception as exc:  # noqa: BLE001 - plugin code: that module's fault
                # A module without its periodic work (a controller, a stall guard) must not
                # run at all: faulted for good.
                self.robot.plugin_bug(slot, "tasks", exc, now)
                slot.retry_at = math.inf
                continue
            for task in tasks:
                rate = self._divisor_rate(task.rate_hz)
                if abs(rate - task.rate_hz) > 1e-9:
                    log.info("task %s.%s runs at %g Hz (asked %g Hz; base rate %g Hz)",
                             slot.name, task.name, rate, task.rate_hz, sched.rate_hz)
                sched.add_task(f"{slot.name}.{task.name}", rate,
                               self._module_task(slot, task.name, task.run))
        self._idle_ticks(sched)
        self.server.start()
        self.running = True
        if self.observer is not None:
            self.observer.started(self)

    def _idle_ticks(self, sched: Scheduler) -> None:
        """Idle ticks (`scheduler.idle_rate_hz`, `ramp.runtime.build.idle_rate`): slower while
        nothing moves, the base rate from the request that arms the watchdog on."""
        if sched.idle_stride > 1:
            sched.idle = self.at_rest
            self.robot.watchdog.on_arm = sched.hurry

    def at_rest(self) -> bool:
        """Nothing moves or is about to: no client commands motion (the watchdog is not
        armed) and every bus is ready and at rest. The loop ticks at its idle rate then."""
        return self.robot.watchdog.state != "armed" and self.bus_manager.at_rest()

    def settle(self, limit: float = 2.0, open_limit: float = 0.5) -> None:
        """Run the loop (serving) until every opened bus reports ready, at most `limit` s.

        Boards such as ODrives and Phidgets open at once but answer a moment later; the ready
        line waits for them so a client connecting right after sees its modules attached.
        An open still running after `open_limit` (a device that does not answer) is not
        waited for: its modules attach when it is done.
        """
        start = self.clock.now()
        end = start + limit
        opener = self.bus_manager.opener

        def settled() -> bool:
            now = self.clock.now()
            opening = opener.in_flight and now < start + open_limit
            return now >= end or (not opening and self.bus_manager.settled())

        self.scheduler.run(settled)

    def shutdown(self) -> None:
        """Stop every motor (zeros on the wire), close devices and the server. Idempotent."""
        if self.running or self.bus_manager.any_open():
            if self.running and self.observer is not None:
                self.observer.stopping(self)
            self.running = False
            self.robot.stop_all("shutdown", self.clock.now())
            self.bus_manager.close_all()  # zeros on the wire first, then the ports close
            self.server.close()
            if self.latch_state is not None:  # a latch of the last moments is kept too
                self.latch_state.check(self.clock.now(), 0.0)
        self._close_recorder()

    # -- the flight recorder ------------------------------------------------------------------
    def _start_recorder(self, now: float) -> None:
        """Recording starts before the buses open, so the modules' attachment is recorded.
        The first file is opened by the recorder's writer thread: a slow or unwritable
        disk never holds the start-up, it only costs records (counted in `robot.get`)."""
        assert self.recorder is not None
        self.recorder.start(now, wait_for_file=False)
        self._log_handler = self.recorder.log_handler(self.clock.now)
        logging.getLogger("ramp").addHandler(self._log_handler)

    def _close_recorder(self) -> None:
        """After the motors have stopped: the last records written, the file indexed."""
        from ramp.runtime.recording import CLOSE_TIMEOUT_S

        if self._log_handler is not None:
            logging.getLogger("ramp").removeHandler(self._log_handler)
            self._log_handler = None
        if self.recorder is not None:
            self.recorder.close(CLOSE_TIMEOUT_S)

    # -- stalls -------------------------------------------------------------------------------
    def stop_all_motors(self, alive_mark: float, lock_wait: float = 0.02) -> None:
        """Last resort (the stall guard's thread, the loop silent since `alive_mark`): zeros
        straight to every driver the loop is not inside. The loop, when it runs again, treats
        this as a stall, so the layers above agree with the wire."""
        self.scheduler.request_stall_stop(alive_mark)
        self.bus_manager.zeros_from_another_thread(lock_wait)

    def on_stall(self, gap: float, unit: str) -> None:
        """The loop lost more than `stall_limit` (SPEC 2.2). Before anything else goes out:
        zeros on every wire, which also turns every queued command and every refresh value
        into a zero; then every module stops and the watchdog trips."""
        now = self.clock.now()
        self.bus_manager.zeros_everywhere()
        self.robot.stalled("tick loop stalled", now)
        self.stall_guard.loop_stalled(gap, unit)
        if self.observer is not None:
            self.observer.stall(now, gap, unit)

    # -- buses and modules --------------------------------------------------------------------
    def buses_changed(self, now: float) -> None:
        """A bus opened, failed or changed readiness: attach or fault the modules on it."""
        self.robot.changes += 1  # a module may stop (fault) outside a tick: the version moves
        self.registry.update(now, self.bus_manager.ready, self.bus_manager.why)
        if not self.robot.any_moving():
            self.robot.watchdog.disarm(now)

    # -- a module's task raising: that module's fault (SPEC 2.2) ----------------------------
    def _module_task(self, slot: ModuleSlot, name: str,
                     run: Callable[[float, float], None]) -> Callable[[float, float], None]:
        """Run only while the module is attached; an exception faults that module alone."""
        def task(now: float, dt: float) -> None:
            if slot.state == "ok":
                try:
                    run(now, dt)
                except Exception as exc:  # noqa: BLE001 - one module's bug, not the loop's
                    self.module_bug(slot, name, exc, now)
        return task

    def module_bug(self, slot: ModuleSlot, task: str, exc: Exception, now: float) -> None:
        """A module's task raised: the module goes to `fault` (its motors zeroed on the
        wire), the traceback is logged once per fault episode, and it is attached again after
        RETRY_PERIOD, as a bus is retried; the rest of the robot keeps running."""
        self.robot.plugin_bug(slot, f"task {task}", exc, now)
        if not self.robot.any_moving(now):
            self.robot.watchdog.disarm(now)

    def _retry_modules(self, now: float, dt: float) -> None:
        """About once a second: attach again a module whose code raised, once its wait is
        over (its buses permitting); end the fault episodes of modules running clean."""
        for slot in self.slots.values():
            slot.quiet(now)
        if any(s.state != "ok" and s.retry_at and now >= s.retry_at
               for s in self.slots.values()):
            self.buses_changed(now)

    def _divisor_rate(self, wanted_hz: float) -> float:
        """The rate nearest `wanted_hz` that divides the base rate (at most the base rate)."""
        divisor = max(1, round(self.scheduler.rate_hz / wanted_hz))
        return self.scheduler.rate_hz / divisor


