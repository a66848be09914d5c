"""Robot distribution layer: routes requests to modules and owns the robot-wide rules.

Module state, control ownership and the watchdog live here because they concern the whole
robot; each module's own table does the device/function/parameter checks. Checks run in the
SPEC's order: module known, module state, device and function, parameters, ownership.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Literal

from ramp.errors import DeviceError, RequestError
from ramp.layers.module_distribution import Function, Module
from ramp.layers.robot_distribution.control import Control
from ramp.layers.robot_distribution.watchdog import MAX_TIMEOUT_S, MIN_TIMEOUT_S, Watchdog
from ramp.mcp.messages import Request, Response, Value, error_response
from ramp.mcp.params import FloatParam, NameParam

log = logging.getLogger("ramp.robot")

ModuleState = Literal["ok", "fault", "detached"]


@dataclass
class ModuleSlot:
    """A known module and whether it is usable now."""

    name: str
    module: Module
    buses: tuple[str, ...] = ()
    state: ModuleState = "detached"
    reason: str = "not started"
    tasks: list[object] = field(default_factory=list)


@dataclass(frozen=True)
class Health:
    """Supervisor figures the robot layer reports but does not own."""

    uptime: float
    rate_hz: float
    late_us: tuple[float, float, float]
    overruns: int
    clients: int


class Client:
    """What the robot layer needs to know of a connection: identity and a printable peer."""

    def __init__(self, peer: str) -> None:
        self.peer = peer

    def __repr__(self) -> str:
        return f"Client({self.peer})"


class RobotRequests(Module):
    """The `robot` module's table: robot-level requests of SPEC 2.1 and 2.2."""

    def __init__(self, layer: RobotDistribution) -> None:
        super().__init__("robot")
        self.layer = layer
        self.add(Function("robot", "modules", (), layer.list_modules, "read",
                          "list attached modules"))
        self.add(Function("watchdog", "timeout", (FloatParam(MIN_TIMEOUT_S, MAX_TIMEOUT_S),),
                          layer.set_timeout, "state", "watchdog timeout in s"))
        self.add(Function("control", "acquire", (NameParam(reserved=("none",)),),
                          layer.acquire, "control", "become the owner (stops motion first)"))
        self.add(Function("control", "release", (), layer.release, "state",
                          "give control up"))

    def _get(self) -> list[Response]:
        return self.layer.health_rows()

    #: The rows of `robot.get`: (device, property, type, unit).
    HEALTH_ROWS = (("robot", "uptime", "float", "s"), ("tick", "rate", "float", "Hz"),
                   ("tick", "late", "int", "us"), ("tick", "overruns", "int", ""),
                   ("watchdog", "timeout", "float", "s"), ("watchdog", "state", "name", ""),
                   ("control", "owner", "name", ""), ("clients", "count", "int", ""))

    def describe(self) -> list[Response]:
        out = [Response("robot", "robot", "module", (name,)) for name in self.layer.slots]
        for fn in self.functions.values():
            out.append(Response("robot", fn.device, "function",
                                (fn.name, *(p.describe() for p in fn.params))))
        for device, prop, kind, unit in self.HEALTH_ROWS:
            out.append(Response("robot", device, "property",
                                (prop, kind, unit) if unit else (prop, kind)))
        out.extend(Response("robot", name, "property", ("state", "name"))
                   for name in self.layer.slots)
        return out

    def stop(self) -> None:
        self.layer.stop_all("robot.stop")

    def is_moving(self) -> bool:
        return False


class RobotDistribution:
    """Routes each request of a message and applies watchdog and arbitration rules."""

    def __init__(self, slots: dict[str, ModuleSlot], watchdog: Watchdog,
                 health: Callable[[], Health]) -> None:
        self.slots = slots
        self.watchdog = watchdog
        self.control = Control()
        self._health = health
        self.robot = RobotRequests(self)
        self._client: Client | None = None
        self._now = 0.0
        #: Called with (module name, error) when a request hit a device fault.
        self.on_device_error: Callable[[str, DeviceError], None] | None = None

    # -- messages -----------------------------------------------------------------------------
    def handle(self, client: Client, requests: tuple[Request, ...], now: float,
               tail: Response | None = None) -> list[Response]:
        """Every request of one message, in order; `tail` (a syntax error) ends the answer."""
        return [r for part in self.handle_steps(client, requests, now, tail) for r in part]

    def handle_steps(self, client: Client, requests: tuple[Request, ...], now: float,
                     tail: Response | None = None) -> Iterator[list[Response]]:
        """The same, one request per step, so the server can pause between requests.

        Every complete message feeds the watchdog if its sender is the feeder, as soon as it
        has arrived (before its requests, which may be answered over several turns).
        """
        self.watchdog.feed(client, now)
        for req in requests:
            yield self._one(client, req, now)
        if tail is not None:
            yield [tail]

    def feed(self, client: Client, now: float) -> None:
        """A complete message that carried no requests we could read (too long) still feeds."""
        self.watchdog.feed(client, now)

    def _one(self, client: Client, req: Request, now: float) -> list[Response]:
        if req.module == "robot":
            target: Module = self.robot
        else:
            slot = self.slots.get(req.module)
            if slot is None:
                known = " ".join(["robot", *self.slots])
                return [error_response(req.module, req.device, "unknown_module",
                                       f"no module {req.module}; known: {known}")]
            if slot.state != "ok":
                if req.device == req.module and req.function == "stop" and not req.params:
                    return []  # its motion is already stopped
                code = "not_attached" if slot.state == "detached" else "fault"
                return [error_response(req.module, req.device, code,
                                       f"module {slot.name} is {slot.state}: {slot.reason}")]
            target = slot.module
        try:
            fn, values = target.lookup(req)
        except RequestError as exc:
            return [error_response(req.module, req.device, exc.code, exc.detail)]
        if fn.kind in ("motion", "state") and not self.control.may_command(client):
            return [error_response(req.module, req.device, "not_owner",
                                   f"control is held by {self.control.owner_name}")]
        self._client, self._now = client, now
        try:
            result = fn.run(*values)
        except RequestError as exc:
            return [error_response(req.module, req.device, exc.code, exc.detail)]
        except DeviceError as exc:
            self._half_done(fn, target)
            if self.on_device_error is not None:
                self.on_device_error(req.module, exc)
            return [error_response(req.module, req.device, "fault", str(exc))]
        except Exception as exc:
            log.exception("request %s:%s.%s failed", req.module, req.device, req.function)
            self._half_done(fn, target)
            return [error_response(req.module, req.device, "fault",
                                   f"internal error {type(exc).__name__}")]
        finally:
            self._client = None
        self._after(fn, client, now)
        return result or []

    def _half_done(self, fn: Function, target: Module) -> None:
        """A motion request that failed part-way may have started some motors with the
        watchdog idle: stop that module."""
        if fn.kind == "motion":
            try:
                target.stop()
            except Exception:
                log.exception("module %s failed to stop", target.name)

    def _after(self, fn: Function, client: Client, now: float) -> None:
        """Watchdog bookkeeping once a request was accepted."""
        if fn.kind == "motion":
            if self.any_moving():
                self.watchdog.arm(client, now)
            else:
                self.watchdog.reset()
        elif fn.kind == "stop" and not self.any_moving():
            self.watchdog.disarm()

    # -- robot-level functions ----------------------------------------------------------------
    def list_modules(self) -> list[Response]:
        names: tuple[Value, ...] = tuple(n for n, s in self.slots.items() if s.state == "ok")
        return [Response("robot", "robot", "modules", names)]

    def set_timeout(self, seconds: float) -> None:
        self.watchdog.timeout = seconds
        log.info("watchdog timeout set to %.3f s by %s", seconds, self._peer())

    def acquire(self, name: str) -> None:
        client = self._client
        assert client is not None
        previous = self.control.owner_name
        if self.control.acquire(client, name):
            self.stop_all(f"control acquired by {name}")
            if previous != "none":
                log.warning("control taken over: %s -> %s (%s); motion stopped",
                            previous, name, client.peer)
            else:
                log.info("control acquired by %s (%s)", name, client.peer)

    def release(self) -> None:
        client = self._client
        if client is not None and self.control.owner is client:
            log.info("control released by %s (%s)", self.control.owner_name, client.peer)
            self.control.release(client)

    def _peer(self) -> str:
        return self._client.peer if self._client is not None else "?"

    # -- robot-wide safety --------------------------------------------------------------------
    def any_moving(self) -> bool:
        return any(s.state == "ok" and s.module.is_moving() for s in self.slots.values())

    def stop_all(self, reason: str) -> None:
        """Every attached module stops all motion; nothing is left for the watchdog."""
        self._stop_keep_trip(reason)
        self.watchdog.disarm()

    def tick(self, now: float, dt: float) -> None:
        """Scheduler task: the watchdog timer."""
        if self.watchdog.expired(now):
            peer = getattr(self.watchdog.feeder, "peer", "?")
            log.warning("watchdog expired: %s silent for %.2f s; stopping every module",
                        peer, now - self.watchdog.last_feed)
            self._stop_keep_trip("watchdog expired")

    def stalled(self, reason: str) -> None:
        """The loop lost time (SPEC 2.2, stalls and freezes): every attached module stops and
        the watchdog reads `tripped` until the next accepted motion request."""
        self._stop_keep_trip(reason)
        self.watchdog.trip()

    def protects(self, client: Client) -> bool:
        """The owner, and the feeder of an armed watchdog, keep their connection when the
        server must make room for a newcomer."""
        return self.control.owner is client or (
            self.watchdog.state == "armed" and self.watchdog.feeder is client)

    def client_lost(self, client: Client) -> None:
        if self.control.owner is client:
            log.info("control released: owner %s (%s) disconnected",
                     self.control.owner_name, client.peer)
            self.control.release(client)
        if self.watchdog.client_lost(client):
            log.warning("watchdog tripped: commanding client %s disconnected; stopping every"
                        " module", client.peer)
            self._stop_keep_trip("commanding client lost")

    def _stop_keep_trip(self, reason: str) -> None:
        """Every attached module stops; the watchdog state is left to the caller."""
        for slot in self.slots.values():
            if slot.state == "ok":
                try:
                    slot.module.stop()
                except Exception:
                    log.exception("module %s failed to stop (%s)", slot.name, reason)

    # -- health -------------------------------------------------------------------------------
    def health_rows(self) -> list[Response]:
        h = self._health()
        p50, p99, mx = h.late_us
        rows = [
            Response("robot", "robot", "uptime", (round(h.uptime, 3),)),
            Response("robot", "tick", "rate", (h.rate_hz,)),
            Response("robot", "tick", "late", (int(p50), int(p99), int(mx))),
            Response("robot", "tick", "overruns", (h.overruns,)),
            Response("robot", "watchdog", "timeout", (self.watchdog.timeout,)),
            Response("robot", "watchdog", "state", (self.watchdog.state,)),
            Response("robot", "control", "owner", (self.control.owner_name,)),
            Response("robot", "clients", "count", (h.clients,)),
        ]
        rows.extend(Response("robot", name, "state", (slot.state,))
                    for name, slot in self.slots.items())
        return rows
