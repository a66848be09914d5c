"""Robot Distribution layer: routes requests to modules and owns the robot-wide rules.

Module state, control ownership and the watchdog live here because they concern the whole
robot; each module's own table (the module distribution layer) does the device, function and
parameter checks. Checks run in the SPEC's order: module known, module state, device and
function, parameters, ownership, interlocks (`interlocks.Interlocks`, SPEC 11: its own file,
asked once per motion request and run as its own scheduler task).

The server hands each message down as a `RequestContext` (client, time): `message(ctx)` once
(its sender has been heard: what the watchdog asks of each commander), then
`request(ctx, req)` for each of its requests, which returns the request's answer as it goes
on the wire.

**The state's version.** Anything a `get` reports changes only inside a tick (readings,
controllers, LED phases) or through this layer (a request that is not a read, a lost client,
a stall, a robot-wide stop). `changes` counts the second kind; with the scheduler's tick
count it makes the version a module's cached get answer is checked against
(`ramp.layers.module_distribution`), so a cache can never serve a stale answer.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from ramp.errors import RequestError
from ramp.layers.module_distribution import Function, Module
from ramp.layers.module_distribution.router import Version, answer
from ramp.layers.robot_distribution.access import forbidden
from ramp.layers.robot_distribution.context import Client, RequestContext
from ramp.layers.robot_distribution.control import Control
from ramp.layers.robot_distribution.interlocks import Interlocks, speed_param
from ramp.layers.robot_distribution.registry import ModuleRegistry, ModuleSlot
from ramp.layers.robot_distribution.watchdog import MAX_TIMEOUT_S, MIN_TIMEOUT_S, Watchdog
from ramp.mcp.messages import Request, Response, Value, clean_detail, error_response
from ramp.mcp.params import FloatParam, NameParam
from ramp.mcp.protocol import format_response

log = logging.getLogger("ramp.robot")

#: Observer hook: (owner name or "none", the client's peer, clock time) when control changes.
ControlHook = Callable[[str, str, float], None]
#: Observer hook (SPEC 13, audit): (client, request, "accepted" or the refusal's code, clock
#: time) for every state-changing request, accepted or refused.
AuditHook = Callable[[Client, Request, str, float], None]


@dataclass(frozen=True)
class Health:
    """Supervisor figures the robot layer reports but does not own."""

    uptime: float
    rate_hz: float
    late_us: tuple[float, float, float]
    overruns: int
    clients: int
    #: Records the flight recorder has lost (a slow or full disk); None when not recording.
    recorder_dropped: int | None = None


class TickCount(Protocol):
    """Whatever counts the scheduler's ticks (its `TickStats`)."""

    ticks: int


class _NoTicks:
    ticks = 0


def _error(req: Request, code: str, detail: str) -> bytes:
    return format_response(error_response(req.module, req.device, code, detail)).encode("ascii")


class RobotRequests(Module):
    """The `robot` module's table: robot-level requests of SPEC 2.1 and 2.2."""

    def __init__(self, layer: RobotDistribution) -> None:
        super().__init__("robot")
        self.layer = layer
        self.add(Function("robot", "modules", (), layer.list_modules, "read",
                          "list attached modules"))
        self.add(Function("watchdog", "timeout", (FloatParam(MIN_TIMEOUT_S, MAX_TIMEOUT_S),),
                          layer.set_timeout, "state", "watchdog timeout in s",
                          takes_context=True))
        self.add(Function("control", "acquire", (NameParam(reserved=("none",)),),
                          layer.acquire, "control", "become the owner (stops motion first)",
                          takes_context=True))
        self.add(Function("control", "release", (), layer.release, "state",
                          "give control up", takes_context=True))
        self.add(Function("interlock", "reset", (NameParam(),), layer.interlock_reset, "state",
                          "clear a latched interlock once its condition has cleared",
                          takes_context=True))
        # The answer depends on the asking client (its own watchdog timeout) and the uptime
        # moves: built for each request, never cached.
        self.add(Function("robot", "get", (), layer.health_rows_for, "read",
                          "every status row", takes_context=True))

    def _get(self) -> list[Response]:
        return self.layer.health_rows()

    #: The rows of `robot.get`: (device, property, type, unit).
    HEALTH_ROWS = (("robot", "uptime", "float", "s"), ("tick", "rate", "float", "Hz"),
                   ("tick", "late", "int", "us"), ("tick", "overruns", "int", ""),
                   ("watchdog", "timeout", "float", "s"), ("watchdog", "state", "name", ""),
                   ("watchdog", "commanders", "int", ""),
                   ("control", "owner", "name", ""), ("clients", "count", "int", ""),
                   ("interlock", "active", "name", ""), ("access", "me", "name", ""))

    def describe(self) -> list[Response]:
        out = [Response("robot", "robot", "module", (name,)) for name in self.layer.slots]
        for rule in self.layer.interlocks.rules:  # SPEC 11: the console's alerts come from these
            out.append(Response("robot", "interlock", "rule", (rule.name, rule.spec.severity)))
            if rule.spec.message:
                out.append(Response("robot", "interlock", "message",
                                    (rule.name, rule.spec.message)))
        for fn in self.functions.values():
            out.append(Response("robot", fn.device, "function",
                                (fn.name, *(p.describe() for p in fn.params))))
        for device, prop, kind, unit in self.HEALTH_ROWS:
            out.append(Response("robot", device, "property",
                                (prop, kind, unit) if unit else (prop, kind)))
        out.extend(Response("robot", name, "property", ("state", "name"))
                   for name in self.layer.slots)
        if self.layer.access_mode is not None:
            out.append(Response("robot", "access", "property", ("mode", "name")))
        if self.layer.recording():
            out.append(Response("robot", "recorder", "property", ("dropped", "int")))
        out.extend(Response("robot", fn.device, "kind", (fn.name, fn.kind))
                   for fn in self.functions.values())
        return out

    def stop(self) -> None:
        # The watchdog is disarmed by the request path (a stop that leaves nothing moving),
        # with the message's time: an observer sees the change when it happened.
        self.layer.stop_modules("robot.stop")

    def is_moving(self) -> bool:
        return False


class RobotDistribution:
    """Routes each request of a message and applies watchdog and arbitration rules."""

    def __init__(self, registry: ModuleRegistry, watchdog: Watchdog,
                 health: Callable[[], Health], ticks: TickCount | None = None,
                 interlocks: Interlocks | None = None) -> None:
        self.registry = registry
        self.slots: dict[str, ModuleSlot] = registry.slots
        self.watchdog = watchdog
        self.control = Control()
        self._health = health
        #: The scheduler's tick count (the runtime passes its TickStats): half of the version.
        self._ticks = ticks if ticks is not None else _NoTicks()
        #: State changes made outside a tick (see the module docstring).
        self.changes = 0
        #: The rules of `interlocks:` bound to the modules (none: nothing is guarded).
        self.interlocks = interlocks if interlocks is not None else Interlocks((), self.slots)
        self.interlocks.on_motion_changed = self._interlock_acted
        self.robot = RobotRequests(self)
        #: Modules outside the registry (the simulator's `sim`): routed like any module, but
        #: they use no bus, are never attached or faulted, and `robot.modules`, `robot.get`
        #: and `robot.stop` leave them out (they move nothing).
        self.extra: dict[str, Module] = {}
        #: Observer hook (the flight recorder): None costs nothing.
        self.on_control: ControlHook | None = None
        #: `robot:access.mode` (SPEC 13): "anonymous" when MCP is open to the network with
        #: no authentication (`access.allow_anonymous`), else None (no row).
        self.access_mode: str | None = None
        #: Observer hook (the flight recorder's audit): None costs nothing.
        self.on_audit: AuditHook | None = None
        #: Clock time of the last tick or request: when a plugin bug met outside both is
        #: dated.
        self.now = 0.0
        #: Read functions that raised, logged once: (module, device, function, type).
        self._broken_reads: set[tuple[str, str, str, str]] = set()

    @property
    def version(self) -> Version:
        return (self._ticks.ticks, self.changes)

    # -- messages -----------------------------------------------------------------------------
    def message(self, ctx: RequestContext) -> None:
        """A complete message arrived (any message: heartbeat, erroneous or too long): its
        sender has been heard, which is what the watchdog asks of a commander (each client
        for itself), before its requests are handled."""
        ctx.client.last_heard = self.now = ctx.now

    def heard(self, client: Client, now: float) -> None:
        """`message` for a caller that has no request context to make (the server's repeat
        answers)."""
        client.last_heard = self.now = now

    def versioned(self, req: Request) -> bool:
        """Whether `req`'s answer is a pure function of `version`: a read answered by its
        function's `line` (a `get`, a `describe`) of a module usable now. Such an answer can
        be kept and given again to the same message while the version holds, by the same
        argument that lets the module keep it (see the module docstring)."""
        module = req.module
        if module == "robot":
            target: Module | None = self.robot
        else:
            slot = self.slots.get(module)
            if slot is not None:
                target = slot.module if slot.state == "ok" else None
            else:
                target = self.extra.get(module)
        if target is None or req.params:
            return False
        fn = target.functions.get((req.device, req.function))
        return fn is not None and fn.kind == "read" and fn.line is not None and not fn.params

    def request(self, ctx: RequestContext, req: Request) -> bytes:
        """One request: its answer as it goes on the wire (b"" for an accepted action)."""
        module = req.module
        slot: ModuleSlot | None = None
        world = False  # a `sim:` request: the world's doing, not the robot's (SPEC 12)
        if module == "robot":
            target: Module = self.robot
        else:
            slot = self.slots.get(module)
            if slot is not None and slot.state == "ok":
                target = slot.module
            elif slot is None and module in self.extra:
                target = self.extra[module]
                world = True
            else:
                return self._unusable(req, slot)
        fn = target.functions.get((req.device, req.function))
        if fn is not None and not fn.params and not req.params:
            values: list[Any] = []  # the common case: nothing to convert
        else:
            try:
                fn, values = target.lookup(req)
            except RequestError as exc:
                return _error(req, exc.code, exc.detail)
        kind = fn.kind
        if kind == "read":
            line = fn.line
            try:
                if line is not None:
                    return line((self._ticks.ticks, self.changes))
                return answer(fn.run(ctx, *values) if fn.takes_context else fn.run(*values))
            except RequestError as exc:
                return _error(req, exc.code, exc.detail)
            except Exception as exc:  # noqa: BLE001 - a plugin's read costs its own answer
                self._read_failed(req, exc)
                return _error(req, "fault", f"internal error {type(exc).__name__}")
        audit = self.on_audit
        if ctx.client.role != "admin":  # SPEC 13: what the sender's role permits
            refusal = forbidden(ctx.client.role, kind, module in self.extra)
            if refusal is not None:
                if audit is not None:
                    audit(ctx.client, req, "forbidden", ctx.now)
                return _error(req, "forbidden", refusal)
        # The simulated world's module (`sim`, outside the registry) is exempt: a trainer's
        # fault acts on the world, not the robot (SPEC 12), while the autonomy holds control.
        if (kind == "motion" or kind == "state") and not self.control.may_command(ctx.client) \
                and module not in self.extra:
            if audit is not None:
                audit(ctx.client, req, "not_owner", ctx.now)
            return _error(req, "not_owner", f"control is held by {self.control.owner_name}")
        interlocks = self.interlocks
        if kind == "motion" and interlocks.guards:
            refusal = interlocks.permit(module, fn, values, ctx.now)
            if refusal is not None:
                if audit is not None:
                    audit(ctx.client, req, "interlocked", ctx.now)
                return _error(req, "interlocked", refusal)
        self.changes += 1
        watchdog = self.watchdog
        armed = None
        stops = kind == "stop"
        if kind == "motion" and not world:
            # A zero speed is a stop: its sender commands nothing. Any other motion makes
            # its sender the device's commander and arms the watchdog before the module's
            # code runs (SPEC 2.2): a plugin that raises half-way has armed it all the same.
            sp = speed_param(fn)
            if sp is not None and values[0] == 0:
                stops = True
            else:
                armed = watchdog.command(module, fn.device, ctx.client, ctx.now)
        try:
            result = fn.run(ctx, *values) if fn.takes_context else fn.run(*values)
        except RequestError as exc:
            if armed is not None:
                watchdog.undo(armed, ctx.now)
            if audit is not None:
                audit(ctx.client, req, exc.code, ctx.now)
            return _error(req, exc.code, exc.detail)
        except Exception as exc:  # noqa: BLE001 - plugin code: that module's fault
            if slot is None:
                log.exception("request %s:%s.%s failed", req.module, req.device, req.function)
            else:
                self.plugin_bug(slot, f"{req.device}.{req.function}", exc, ctx.now)
            if kind == "motion":
                interlocks.forget(module)
            return _error(req, "fault", f"internal error {type(exc).__name__}")
        if interlocks.rules and (kind == "motion" or kind == "stop"):
            interlocks.ran(module, fn, values)
        if stops:
            watchdog.stopped(module, fn.device)
        if kind == "motion" and not world:
            watchdog.settle(ctx.now, self.any_moving(ctx.now))
        elif kind == "stop" and not self.any_moving(ctx.now):
            watchdog.disarm(ctx.now)
        if audit is not None:
            audit(ctx.client, req, "accepted", ctx.now)
        return answer(result) if result else b""

    def _read_failed(self, req: Request, exc: Exception) -> None:
        """A read function raised: nothing moves on a read, so the module keeps working and
        only this answer is an error; the traceback is logged once per function."""
        key = (req.module, req.device, req.function, type(exc).__name__)
        if key not in self._broken_reads:
            self._broken_reads.add(key)
            log.error("%s:%s.%s raised (logged once; it answers fault while it raises, the "
                      "module keeps working)", req.module, req.device, req.function,
                      exc_info=exc)

    def _unusable(self, req: Request, slot: ModuleSlot | None) -> bytes:
        """A request to a module that is unknown, or not attached (SPEC 2's order)."""
        if slot is None:
            known = " ".join(["robot", *self.slots, *self.extra])
            return _error(req, "unknown_module", f"no module {req.module}; known: {known}")
        if req.device == req.module and req.function == "stop" and not req.params:
            return b""  # its motion is already stopped
        code = "not_attached" if slot.state == "detached" else "fault"
        return _error(req, code, f"module {slot.name} is {slot.state}: {slot.reason}")

    def add_extra(self, module: Module) -> None:
        """Route requests to `module` beside the registry's (see `extra`)."""
        if module.name == "robot" or module.name in self.slots or module.name in self.extra:
            raise ValueError(f"a module named {module.name} already exists")
        self.extra[module.name] = module

    # -- robot-level functions ----------------------------------------------------------------
    def list_modules(self) -> list[Response]:
        names: tuple[Value, ...] = tuple(self.registry.attached())
        return [Response("robot", "robot", "modules", names)]

    def set_timeout(self, ctx: RequestContext, seconds: float) -> None:
        """The sender's own timeout, for as long as it is connected (SPEC 2.2): no other
        client's changes."""
        ctx.client.timeout = seconds
        log.info("watchdog timeout of %s set to %.3f s", ctx.client.peer, seconds)

    def acquire(self, ctx: RequestContext, name: str) -> None:
        client = ctx.client
        if client.tls and name != client.identity:  # SPEC 13: nobody poses as another
            raise RequestError("forbidden", f"you are {client.identity}: acquire as "
                               f"{client.identity}, not {name}")
        previous = self.control.owner_name
        if self.control.acquire(client, name):
            self.stop_all(f"control acquired by {name}", ctx.now)
            if previous != "none":
                log.warning("control taken over: %s -> %s (%s); motion stopped",
                            previous, name, client.peer)
            else:
                log.info("control acquired by %s (%s)", name, client.peer)
        self._control_changed(client, ctx.now)

    def release(self, ctx: RequestContext) -> None:
        client = ctx.client
        if self.control.owner is client:
            log.info("control released by %s (%s)", self.control.owner_name, client.peer)
            self.control.release(client)
            self._control_changed(client, ctx.now)

    def interlock_reset(self, ctx: RequestContext, name: str) -> None:
        """`robot:interlock.reset=(NAME)`: a latched rule whose condition has cleared is
        released; refused (`interlocked`) while it still holds."""
        interlocks = self.interlocks
        if name not in interlocks.by_name:
            known = " ".join(interlocks.by_name) or "none configured"
            raise RequestError("bad_params", f"no interlock {name}; rules: {known}")
        refusal = interlocks.reset(name, ctx.now)
        if refusal is not None:
            raise RequestError("interlocked", refusal)

    def _interlock_acted(self, now: float) -> None:
        """An interlock stopped or slowed motion: the state's version moves, and a watchdog
        left guarding nothing goes idle."""
        self.changes += 1
        if not self.any_moving():
            self.watchdog.disarm(now)

    def _control_changed(self, client: Client, now: float) -> None:
        if self.on_control is not None:
            self.on_control(self.control.owner_name, client.peer, now)

    # -- robot-wide safety --------------------------------------------------------------------
    def any_moving(self, now: float | None = None) -> bool:
        """Any attached module moving. A module whose `is_moving` raises goes to `fault`
        (its motors zeroed by the bus layer) and moves no more."""
        moving = False
        for slot in self.slots.values():
            if slot.state == "ok" and self._is_moving(slot, now):
                moving = True
        return moving

    def moving(self, module: str) -> bool:
        """The module is attached and moving (its commanders must keep talking)."""
        slot = self.slots.get(module)
        return slot is not None and slot.state == "ok" and self._is_moving(slot, None)

    def _is_moving(self, slot: ModuleSlot, now: float | None) -> bool:
        try:
            return bool(slot.module.is_moving())
        except Exception as exc:  # noqa: BLE001 - plugin code on the safety path
            self.plugin_bug(slot, "is_moving", exc, self.now if now is None else now)
            return False

    def plugin_bug(self, slot: ModuleSlot, where: str, exc: Exception, now: float) -> None:
        """Plugin code of `slot`'s module raised on the safety path (SPEC 2.2): the module
        goes to `fault`, its motors zeroed by the bus layer (never trusting its own stop),
        one traceback per fault episode; the rest keep running."""
        self.changes += 1
        slot.plugin_bug(where, exc, now)

    def stop_all(self, reason: str, now: float = 0.0) -> None:
        """Every attached module stops all motion; nothing is left for the watchdog."""
        self._stop_keep_trip(reason)
        self.watchdog.disarm(now)

    def tick(self, now: float, dt: float) -> None:
        """Scheduler task: is any commander of a moving module late? Then everything stops."""
        watchdog = self.watchdog
        self.now = now
        if watchdog.state != "armed":
            return
        late = watchdog.late(now, self.moving)
        if late is not None:
            module, client = late
            log.warning("watchdog expired: %s silent for %.2f s (its timeout %.3g s) while "
                        "commanding %s; stopping every module", client.peer,
                        now - client.last_heard, watchdog.timeout_of(client), module)
            self._stop_keep_trip("watchdog expired")
            watchdog.trip("expired", now)

    def stalled(self, reason: str, now: float = 0.0) -> None:
        """The loop lost time (SPEC 2.2, stalls and freezes): every attached module stops and
        the watchdog reads `tripped` until the next accepted motion request."""
        self._stop_keep_trip(reason)
        self.watchdog.trip(reason, now)

    def protects(self, client: Client) -> bool:
        """The owner, and every commander of a moving module, keep their connection when
        the server must make room for a newcomer (evicting a commander would stop it)."""
        return self.control.owner is client or self.watchdog.commands_moving(
            client, self.moving)

    def client_lost(self, client: Client, now: float = 0.0) -> None:
        self.changes += 1
        if self.control.owner is client:
            log.info("control released: owner %s (%s) disconnected",
                     self.control.owner_name, client.peer)
            self.control.release(client)
            self._control_changed(client, now)
        lost = self.watchdog.client_lost(client, self.moving)
        if lost:
            log.warning("watchdog tripped: commanding client %s disconnected (it commanded "
                        "%s); stopping every module", client.peer, " ".join(lost))
            self._stop_keep_trip("commanding client lost")
            self.watchdog.trip("commander lost", now)

    def stop_modules(self, reason: str) -> None:
        """Every attached module stops; the watchdog state is left to the caller."""
        self._stop_keep_trip(reason)

    def _stop_keep_trip(self, reason: str) -> None:
        """Every attached module stops; the watchdog state is left to the caller. Its
        motors are zeroed on the wire by the bus layer as well: a module's own `stop` is
        plugin code, and a stop it cannot complete must not leave a motor running."""
        self.changes += 1
        self.interlocks.stopped_all()  # a limit never re-runs what this stops
        for slot in self.slots.values():
            if slot.state == "ok":
                self._stop_slot(slot, reason)

    def _stop_slot(self, slot: ModuleSlot, reason: str) -> None:
        try:
            slot.module.stop()
        except Exception as exc:  # noqa: BLE001 - plugin code: that module's fault
            self.plugin_bug(slot, f"stop ({reason})", exc, self.now)
        slot.zero()

    # -- health -------------------------------------------------------------------------------
    def health_rows_for(self, ctx: RequestContext) -> list[Response]:
        """`robot.get` as the asking client sees it (its own watchdog timeout)."""
        return self.health_rows(ctx.client)

    def health_rows(self, client: Client | None = None) -> list[Response]:
        """`robot.get`'s rows; the watchdog timeout is `client`'s own (the default when
        None: what a recorder samples)."""
        h = self._health()
        watchdog = self.watchdog
        p50, p99, mx = h.late_us
        rows = [
            Response("robot", "robot", "uptime", (round(h.uptime, 3),)),
            Response("robot", "tick", "rate", (h.rate_hz,)),
            Response("robot", "tick", "late", (int(p50), int(p99), int(mx))),
            Response("robot", "tick", "overruns", (h.overruns,)),
            Response("robot", "watchdog", "timeout", (
                watchdog.timeout if client is None else watchdog.timeout_of(client),)),
            Response("robot", "watchdog", "state", (watchdog.state,)),
            Response("robot", "watchdog", "commanders", (watchdog.count(self.moving),)),
            Response("robot", "control", "owner", (self.control.owner_name,)),
            Response("robot", "clients", "count", (h.clients,)),
        ]
        active = self.interlocks.active_names()
        rows.append(Response("robot", "interlock", "active", active or ("none",)))
        for name, slot in self.slots.items():
            rows.append(Response("robot", name, "state", (slot.state,)))
            if slot.state != "ok" and slot.reason:  # why, beside the state (SPEC 2.3)
                rows.append(Response("robot", name, "reason", (clean_detail(slot.reason),)))
        if client is not None:
            rows.append(Response("robot", "access", "me", (client.identity, client.role)))
        if self.access_mode is not None:
            rows.append(Response("robot", "access", "mode", (self.access_mode,)))
        if h.recorder_dropped is not None:
            rows.append(Response("robot", "recorder", "dropped", (h.recorder_dropped,)))
        return rows

    def recording(self) -> bool:
        """A flight recorder is on (`robot.get` then has `robot:recorder.dropped=(n)`)."""
        return self._health().recorder_dropped is not None
