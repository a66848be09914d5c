"""The buses of a running supervisor: opened off the loop, ticked, watched, retried.

This is where a device fault enters the layers above, by one route: a driver raises
`DeviceError` from its bus's `tick` (or records one in `failure`, seen at once when the loop
finds its descriptor readable), the bus is closed and retried about once a second, and the
module registry faults every module that uses it (`ramp.layers.robot_distribution.registry`:
entering `fault` stops the module and logs). A request never sees an I/O error.

**A bug in one driver is one bus's fault** (SPEC 2.2: plugin code is untrusted on the safety
path). Any other exception out of a driver, wherever the loop calls into it (its open, tick,
input handler, readiness, `waiting`, descriptor, a command, a stop, its close), takes the
same route: that bus is faulted (its close puts zeros on its motors where it still can
write, and the port is closed either way), its modules go to `fault` with their motion
stopped, it is retried as in hot plug, and the rest keep ticking and serving. Its traceback
is logged once per fault episode and place (`where`, exception type: a message that carries
a counter or a time is the same bug), not at every tick or retry; a repeat is one quiet
line. An episode ends once the bus has been ready for `QUIET_S`.

A bus with a descriptor (`Bus.fileno()`: a serial port, a CAN socket) is watched by the loop
while it is open, so a hang-up or input is handled the moment it happens instead of being
polled for every tick.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from ramp.errors import DeviceError
from ramp.hal.interfaces import Bus, MotorChannel, ServoChannel
from ramp.registry import origin
from ramp.runtime.bus_opener import BusOpener
from ramp.scheduler import Scheduler

log = logging.getLogger("ramp.supervisor")

RETRY_PERIOD = 1.0  # seconds between attempts to reopen a missing device
#: A bus ready this long (s) ends its fault episode: its next driver bug logs a traceback.
QUIET_S = 30.0

#: Observer hook: (bus, reason, clock time) when a bus fails and is closed.
FaultHook = Callable[[str, str, float], None]


@dataclass
class BusHealth:
    """Why a bus is closed, and when to try it again."""

    reason: str = "not opened yet"
    next_retry: float = 0.0
    faults: int = 0
    #: Driver bugs already logged with their traceback in this fault episode: (where,
    #: exception type); the message is left out, since it may carry a counter or a time.
    bugs: set[tuple[str, str]] = field(default_factory=set)
    #: Clock time the bus last became ready (its fault episode ends QUIET_S after).
    ready_since: float = 0.0


def zeroer(channels: list[object]) -> Callable[[], None]:
    """What stops one module's motion on the wire, whatever its own code does (SPEC 2.2:
    plugin code is untrusted): zero on each of its motor channels, its servos held where
    they are, written by the bus layer. A driver that raises on it faults its bus (whose
    close writes zeros to every motor it drives)."""
    motors = [c for c in channels if isinstance(c, MotorChannel)]
    servos = [c for c in channels if isinstance(c, ServoChannel)]

    def zero() -> None:
        for m in motors:
            bus = m.bus
            if bus is None:
                m.duty = 0.0
                m._apply(0.0)
            else:
                bus.command_motor(m, 0.0)
        for sv in servos:
            sv.hold()

    return zero


class BusManager:
    """Every bus of the robot, by name."""

    def __init__(self, buses: Mapping[str, Bus], scheduler: Scheduler,
                 on_change: Callable[[float], None]) -> None:
        self.buses = dict(buses)
        self.scheduler = scheduler
        self.clock = scheduler.clock
        self.health = {name: BusHealth() for name in self.buses}
        self.opener = BusOpener(inline=self.clock.virtual)
        #: Called after a bus opened, failed or changed readiness (the registry updates).
        self._on_change = on_change
        #: Observer hook (the flight recorder): None costs nothing.
        self.on_fault: FaultHook | None = None
        self._ready = {name: False for name in self.buses}
        self._waiting = True  # some open bus is not ready yet: each tick asks again
        #: What each bus last said it waits for (logged once), and the buses that were down
        #: (failed, or waiting) and will be reported "back" when they are ready again.
        self._told: dict[str, str] = {}
        self._down: set[str] = set()
        self._watched: dict[str, int] = {}
        #: A closed bus's reason changed (a reopen failed otherwise): the next refresh tells.
        self._reasons_changed = False
        for bus in self.buses.values():
            bus.gate = scheduler.on_time  # motion computed before a stall never goes out

    # -- what the registry asks ---------------------------------------------------------------
    def ready(self, name: str) -> bool:
        return self._ready[name]

    def why(self, name: str) -> str:
        return self.health[name].reason or "not ready"

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Open every bus, in parallel (each open has its own thread); missing ones are
        retried later."""
        for name, bus in self.buses.items():
            self._try_open(name, bus, now)
        for name, bus in self.buses.items():
            if self.opener.busy(name):  # a second look once all have started
                self._try_open(name, bus, now)
        self._refresh(now, force=True)

    def settled(self) -> bool:
        """Every open bus answers (boards that attach asynchronously included); a driver
        whose readiness raises is faulted by the next refresh, and counts as settled."""
        for bus in self.buses.values():
            try:
                if bus.is_open and not bus.ready():
                    return False
            except Exception:  # noqa: BLE001 - a driver bug: faulted by `_refresh`
                continue
        return True

    def at_rest(self) -> bool:
        """No open is in flight, every open bus is ready and at rest (`Bus.at_rest`): the loop
        may tick at its idle rate. A driver whose check raises counts as busy (its next tick
        faults it if it is broken)."""
        if self.opener.in_flight or self._waiting:
            return False
        for bus in self.buses.values():
            try:
                if bus.is_open and not bus.at_rest():
                    return False
            except Exception:  # noqa: BLE001 - plugin driver code: never idle on a doubt
                return False
        return True

    def close_all(self) -> None:
        """Zeros on every wire, then every port closes. Idempotent; a driver that raises
        while closing never keeps the other buses open."""
        self.opener.cancel_all()
        for name, bus in self.buses.items():
            self._unwatch(name)
            try:
                bus.close()
            except Exception as exc:  # noqa: BLE001 - every other bus must still close
                log.error("bus %s (%s): the driver raised while closing: %s: %s", name,
                          bus.driver_name, type(exc).__name__, exc)

    def any_open(self) -> bool:
        return any(b.is_open for b in self.buses.values())

    # -- scheduler tasks ----------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        """Every base tick: collect opens that were in flight, tick every open bus."""
        if self.opener.in_flight:
            self._collect_opens(now)
        for name, bus in self.buses.items():
            if not bus.is_open:
                continue
            try:
                bus.tick(now, dt)
            except DeviceError as exc:
                self.fault(name, exc, now)
            except Exception as exc:  # noqa: BLE001 - a driver bug: this bus's fault only
                self.driver_bug(name, exc, "tick", now)
        if self._waiting:
            self._refresh(now)

    def retry(self, now: float, dt: float) -> None:
        """About once a second: reopen what is closed; end the fault episodes of buses that
        have been ready for QUIET_S."""
        for name, bus in self.buses.items():
            health = self.health[name]
            if (not bus.is_open and not self.opener.busy(name)
                    and now >= health.next_retry):
                self._try_open(name, bus, now)
            elif health.bugs and self._ready[name] and now - health.ready_since >= QUIET_S:
                self._quiet(name, bus)
        self._refresh(now)

    def _quiet(self, name: str, bus: Bus) -> None:
        """Bus `name`'s fault episode is over: its next bug logs its traceback again."""
        self.health[name].bugs.clear()
        self.opener.forget(name)
        bus._bug_logged = False

    # -- faults -------------------------------------------------------------------------------
    def driver_bug(self, name: str, exc: Exception, where: str, now: float) -> None:
        """An unexpected exception out of bus `name`'s driver: its traceback once, then the
        device-fault route (the bus closes, is retried, its modules fault)."""
        bus = self.buses[name]
        key = (where, type(exc).__name__)
        health = self.health[name]
        detail = f"driver error in {where}: {key[1]}: {exc}".rstrip(": ")
        if key not in health.bugs:
            health.bugs.add(key)
            log.error("bus %s: the driver raised in %s (%s); the bus is faulted and "
                      "retried, the other buses keep running (its traceback is logged once "
                      "per fault episode)", name, where, origin("ramp.drivers", bus.driver_name),
                      exc_info=exc)
            self.fault(name, DeviceError(name, detail), now)
        else:
            self.fault(name, DeviceError(name, detail), now, quiet=True)

    def fault(self, name: str, exc: DeviceError, now: float, quiet: bool = False) -> None:
        """The one route of a device fault: close the bus, retry later, let the registry
        fault its modules. `quiet`: a repeat already reported (logged at debug level)."""
        health = self.health[name]
        health.faults += 1
        health.reason = exc.detail
        health.next_retry = now + RETRY_PERIOD
        log.log(logging.DEBUG if quiet else logging.ERROR, "bus %s fault: %s", name, exc.detail)
        self._down.add(name)
        self._unwatch(name)
        try:
            self.buses[name].close()
        except Exception as bug:  # noqa: BLE001 - a closing bug must not stop the fault
            key = ("close", type(bug).__name__)
            if key not in health.bugs:  # once per fault episode, as any driver bug
                health.bugs.add(key)
                log.error("bus %s (%s): the driver raised while closing (its port is "
                          "treated as closed)", name, self.buses[name].driver_name,
                          exc_info=bug)
        if self.on_fault is not None:
            self.on_fault(name, exc.detail, now)
        self._refresh(now, force=True)  # its modules' reasons say the fault's own

    # -- stops --------------------------------------------------------------------------------
    def zeros_everywhere(self) -> None:
        """Zeros on every open wire now (the stall handler's first act). A driver that
        cannot write them is faulted: its port is closed (after the other buses stopped)."""
        broken: list[tuple[str, Exception]] = []
        for name, bus in self.buses.items():
            if not bus.is_open:
                continue
            try:
                bus.stop_motors()
            except Exception as exc:  # noqa: BLE001 - every other bus must still stop
                broken.append((name, exc))
        now = self.clock.now()
        for name, raised in broken:
            if isinstance(raised, DeviceError):
                self.fault(name, raised, now)
            else:
                self.driver_bug(name, raised, "stop_motors", now)

    def zeros_from_another_thread(self, lock_wait: float) -> None:
        """The stall guard's last resort: zeros through every driver the loop is not inside
        (see the bus lock in `ramp.hal.interfaces`)."""
        for name, bus in self.buses.items():
            try:
                if not bus.try_stop_motors(lock_wait):
                    log.error("bus %s: the tick loop is stuck inside its driver; its motors "
                              "are left to the controller's own timeout", name)
            except Exception as exc:  # noqa: BLE001 - every other bus must still stop
                log.error("bus %s: could not stop motors: %s", name, exc)

    # -- internals ----------------------------------------------------------------------------
    def _refresh(self, now: float, force: bool = False) -> None:
        """Tell the registry when a bus's readiness changed (boards attach, buses fail)."""
        changed = force or self._reasons_changed
        self._reasons_changed = False
        buggy: list[tuple[str, str, Exception]] = []
        for name, bus in self.buses.items():
            try:
                ready = bus.is_open and bus.ready()
            except Exception as bug:  # noqa: BLE001 - a driver bug: faulted below
                ready = False
                buggy.append((name, "ready", bug))
            if ready != self._ready[name]:
                self._ready[name] = ready
                changed = True
                if ready:
                    self.health[name].ready_since = now
                    self._told.pop(name, None)
                    if name in self._down:
                        self._down.discard(name)
                        log.info("bus %s is back", name)
            elif not ready and bus.is_open:
                try:
                    waiting = bus.waiting()
                except Exception as bug:  # noqa: BLE001 - a driver bug: faulted below
                    buggy.append((name, "waiting", bug))
                    continue
                if waiting and self._told.get(name) != waiting:
                    self._told[name] = waiting
                    self._down.add(name)
                    self.health[name].reason = waiting
                    log.warning("bus %s (%s) %s", name, bus.driver_name, waiting)
        # An open bus becomes ready only in its own tick (a board attaches); it stops being
        # ready only by failing, which refreshes too: with every open bus ready, the ticks
        # need not ask again.
        self._waiting = any(b.is_open and not self._ready[n] for n, b in self.buses.items())
        if changed:
            self._on_change(now)
        for name, where, raised in buggy:
            if self.buses[name].is_open:  # not already faulted by an earlier one
                self.driver_bug(name, raised, where, now)

    def _try_open(self, name: str, bus: Bus, now: float) -> bool:
        """Open a bus without holding the loop (see `ramp.runtime.bus_opener`); True once it
        is open (and watched). A failure waits RETRY_PERIOD before the next try; an open still
        running is looked at again on the next tick."""
        result = self.opener.open(name, bus, now)
        if result is False:
            return False
        health = self.health[name]
        if isinstance(result, DeviceError):
            self._down.add(name)
            if health.reason != result.detail:
                self._reasons_changed = True  # its modules' reasons say the new one
                log.warning("bus %s (%s) unavailable: %s; retrying every %.0f s", name,
                            bus.driver_name, result.detail, RETRY_PERIOD)
            health.reason = result.detail
            health.next_retry = now + RETRY_PERIOD
            return False
        health.reason = ""
        # Open is not ready (a Phidget board attaches later, if it is there at all): "back"
        # and "waiting" are said by `_refresh` when the bus's readiness shows it.
        log.debug("bus %s (%s) open", name, bus.driver_name)
        try:
            fd = bus.fileno()
        except Exception as bug:  # noqa: BLE001 - a driver bug: this bus's fault
            self.driver_bug(name, bug, "fileno", now)
            return False
        self._watch(name, bus, fd)
        self._waiting = True  # is it ready yet? the next refresh says
        return True

    def _collect_opens(self, now: float) -> None:
        """Opens that were still running: take their results as soon as they are in."""
        for name, bus in self.buses.items():
            if self.opener.busy(name):
                self._try_open(name, bus, now)

    def _watch(self, name: str, bus: Bus, fd: int | None) -> None:
        """Wait on the bus's descriptor in the loop while it is open."""
        if fd is None:
            return
        self._watched[name] = fd
        bus.watched = True
        self.scheduler.add_reader(fd, lambda: self._drain(name, bus))

    def _unwatch(self, name: str) -> None:
        fd = self._watched.pop(name, None)
        if fd is not None:
            self.scheduler.remove_reader(fd)
            self.buses[name].watched = False

    def _drain(self, name: str, bus: Bus) -> None:
        now = self.clock.now()
        try:
            bus.drain(now)
        except Exception as exc:  # noqa: BLE001 - a driver bug: this bus's fault only
            self.driver_bug(name, exc, "input", now)
            return
        if bus.failure is not None:
            self.fault(name, bus.failure, now)
