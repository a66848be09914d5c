"""Module Distribution layer: a table-driven router.

Each module declares its functions and get properties once, as data. Validation, error
responses, `get` and `describe` all come from that one table, so they cannot drift apart,
and a request is validated here and nowhere else: the layers below trust the values they
are handed (they assert, never clamp). The robot distribution layer does the checks that need
the whole robot (module state, ownership, watchdog); this layer finds the function and types
the parameters.

`describe` publishes each function's kind (`MODULE:DEVICE.kind=(FUNCTION,KIND)`), so a
client knows what moves the robot without guessing from names:

- `motion` moves something: owner only, arms the watchdog;
- `stop` stops motion: accepted from anyone, always;
- `state` changes something that does not move (an LED, a tare, a timeout): owner only;
- `read` changes nothing: open to everyone (`get`, `describe`, `robot.modules`);
- `control` is arbitration itself (`control.acquire`: anyone may take over).

**Latched faults** (SPEC 2.2). A device whose component latches a fault (a
`ramp.layers.functional.FaultLatch`: a lift that stalls) is declared once with `latched`;
the module then has `DEVICE.reset=()` (kind `state`, the only thing that clears it), a get row
showing it (`ble:lift.stalled=(1)`), and every motion function of the device refused with
`fault` while it is latched, whoever calls it. Plugin modules get the same by declaring theirs.

**Answers on the wire.** `get_line` writes a module's get rows straight into one
pre-formatted response (each row's `MODULE:DEVICE.PROP=(` prefix is built once), and keeps it
until the robot's state may have changed: the caller passes a version that moves on at every
tick and at every request or event that can change anything (see
`ramp.layers.robot_distribution`). That is correct by construction because readings change
only inside a tick (`ramp.hal.interfaces`: an input returns the sample its bus's tick took)
and everything else a get reports changes only in a tick or through the robot layer.
"""

from __future__ import annotations

import logging
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Literal

from ramp.errors import ConfigError, RequestError
from ramp.mcp.messages import Request, Response, Value, error_response
from ramp.mcp.params import BadParam, Param, convert_all, signature
from ramp.mcp.protocol import format_response, format_value
from ramp.schema import Block, Field, check_block

#: See the module docstring; published by `describe` as `DEVICE.kind=(FUNCTION,KIND)`.
Kind = Literal["motion", "stop", "state", "read", "control"]
KINDS: tuple[Kind, ...] = ("motion", "stop", "state", "read", "control")
#: What a cached answer is valid for: (ticks so far, changes outside ticks so far).
Version = tuple[int, int]

log = logging.getLogger("ramp.modules")


@dataclass(frozen=True)
class Function:
    """One `device.function` a module accepts."""

    device: str
    name: str
    params: tuple[Param, ...]
    #: Runs the request with its typed parameters; get-like functions return their rows.
    run: Callable[..., list[Response] | None]
    kind: Kind = "motion"
    help: str = ""
    #: `run` takes the request context (client, time) first: the robot layer's own requests.
    takes_context: bool = False
    #: For reads: the answer written straight to the wire, given the state's version.
    line: Callable[[Version], bytes] | None = None
    #: For a motion function on the module's own device (`base.drive`): the devices it moves
    #: (the four wheels), so an interlock on any of them covers it (SPEC 11). Left empty, a
    #: function moves its own device, and a module-level one every device of the module
    #: that has motion (the safe guess).
    moves: tuple[str, ...] = ()
    #: The direction each device of `moves` (or the function's own device) would run with
    #: the request's parameters: +1 forward, -1 reverse, 0 not at all, for interlocks that
    #: forbid one direction (SPEC 11); it answers None when it cannot tell. Left None: the
    #: sign of a speed first parameter, else unknown (such a rule refuses it either way).
    senses: Callable[..., Sequence[int] | None] | None = None


@dataclass(frozen=True)
class Property:
    """One row of a module's `get` response."""

    device: str
    name: str
    type: Literal["int", "float"]
    read: Callable[[], Value]
    unit: str = ""


@dataclass(frozen=True)
class DeviceSpec:
    """A hardware device a module expects in YAML: which HAL kind, and its own keys."""

    kind: str  # one of ramp.hal.interfaces.KINDS
    fields: Mapping[str, Field] = field(default_factory=Block)  # a Block: keys and rules
    help: str = ""


@dataclass(frozen=True)
class BoundDevice:
    """A YAML device after the builder made it: its HAL channel and its own keys."""

    channel: Any  # MotorChannel, AnalogInput, DigitalInput, DigitalOutput or BridgeInput
    params: Mapping[str, Any]  # values of DeviceSpec.fields (checked again by the module)


@dataclass(frozen=True)
class Task:
    """Periodic work a module asks the scheduler for."""

    name: str
    rate_hz: float
    run: Callable[[float, float], None]


def _refused_while_latched(fn: Function, latch: Any) -> Function:
    """`fn`, answering `fault` while `latch` is set (see `Module.latched`)."""
    run = fn.run

    def guarded(*args: Any) -> list[Response] | None:
        if latch.reason:
            raise RequestError("fault", f"{latch.reason}; acknowledge it with "
                                        f"{latch.label}.reset")
        return run(*args)

    return replace(fn, run=guarded)


def answer(responses: list[Response] | None) -> bytes:
    """Responses as they go on the wire (no line end): the robot layer's answer to a request."""
    if not responses:
        return b""
    return "".join([format_response(r) for r in responses]).encode("ascii")


class Module(ABC):
    """A module's distribution layer. Subclasses fill `functions` and `properties`.

    `get`, `stop` and `describe` on the module's own device are added here for every module.
    Concrete modules are built as `Cls(name, devices, settings)`: `devices` maps each name of
    `Cls.devices` to a `BoundDevice`, `settings` maps each block of `Cls.settings` to its
    values; both are checked here, against the class's schema (`device`, `setting`).
    """

    #: YAML: the hardware devices this module needs (name -> spec).
    devices: ClassVar[dict[str, DeviceSpec]] = {}
    #: YAML: extra settings blocks (block name -> keys and rules), e.g. calibration.
    settings: ClassVar[dict[str, Block]] = {}

    def __init__(self, name: str) -> None:
        self.name = name
        self.functions: dict[tuple[str, str], Function] = {}
        #: Device -> its latched fault (`latched`); motion functions of a guarded device are
        #: refused while its latch is set.
        self.latches: dict[str, Any] = {}
        self._guarded: dict[str, Any] = {}
        self.properties: list[Property] = []
        self._devices: set[str] = set()
        self._get_version: Version | None = None
        self._get_answer = b""
        self._rows: list[tuple[str, Callable[[], Value], str]] | None = None
        self._describe: bytes | None = None
        self._broken_reads: set[tuple[str, str]] = set()  # properties that raised (logged)
        self.add(Function(name, "get", (), self._get, "read", "every status row",
                          line=self.get_line))
        self.add(Function(name, "stop", (), self._stop_request, "stop", "stop all motion"))
        self.add(Function(name, "describe", (), self.describe, "read", "list functions",
                          line=self.describe_line))

    # -- building -----------------------------------------------------------------------------
    @classmethod
    def device(cls, devices: Mapping[str, Any], name: str, kind: type
               ) -> tuple[Any, dict[str, Any]]:
        """The HAL channel of device `name`, which must be a `kind` channel, and its keys
        checked against this module's schema (the one block check; ConfigError keyed by
        the device)."""
        try:
            bound = devices[name]
        except KeyError:
            raise ConfigError("missing device", key=name) from None
        ch = bound.channel
        if not isinstance(ch, kind):
            raise ConfigError(f"expected a {kind.__name__} channel, got {type(ch).__name__}",
                              key=name)
        return ch, check_block(cls.devices[name].fields, bound.params, name)

    @classmethod
    def setting(cls, settings: Mapping[str, Mapping[str, Any]] | None, block: str
                ) -> dict[str, Any]:
        """Settings block `block`, checked (defaults filled in for what is not given)."""
        return check_block(cls.settings[block], (settings or {}).get(block), block)

    # -- table --------------------------------------------------------------------------------
    def add(self, fn: Function) -> None:
        latch = self._guarded.get(fn.device)
        if latch is not None and fn.kind == "motion":
            fn = _refused_while_latched(fn, latch)
        self.functions[(fn.device, fn.name)] = fn
        self._devices.add(fn.device)
        self._describe = None

    def latched(self, device: str, latch: Any, prop: str = "latched",
                guards: tuple[str, ...] = ()) -> None:
        """Declare `device`'s latched fault (`latch`: a `FaultLatch`, tripped by the device's
        component): adds `DEVICE.reset=()` (kind `state`) and the get row `DEVICE.PROP=(0|1)`,
        and refuses every motion function of the device (and of the devices in `guards`,
        such as a module-wide drive using it) with `fault` while it is latched. The reset is
        refused with `fault` while the latch's `cause` still reads true (SPEC 2.2)."""
        latch.label = f"{self.name}:{device}"
        self.latches[device] = latch
        for d in (device, *guards):
            self._guarded[d] = latch
        for fn in list(self.functions.values()):
            if fn.device in (device, *guards):
                self.add(fn)

        def reset(ctx: Any = None) -> None:
            still = getattr(latch, "still_there", None)
            why = still() if still is not None and latch.latched else ""
            if why:
                raise RequestError("fault", f"{latch.label} stays latched: {why}; reset it "
                                            "once that is fixed")
            latch.clear(getattr(getattr(ctx, "client", None), "peer", ""))

        self.add(Function(device, "reset", (), reset, "state",
                          "acknowledge the latched fault: its motion is accepted again",
                          takes_context=True))
        self.prop(Property(device, prop, "int", lambda: int(latch.latched)))

    def prop(self, p: Property) -> None:
        self.properties.append(p)
        self._devices.add(p.device)
        self._rows = None
        self._describe = None

    def lookup(self, req: Request) -> tuple[Function, list[Any]]:
        """The function a request names with its typed parameters, or RequestError: the one
        place a request is validated."""
        fn = self.functions.get((req.device, req.function))
        if fn is None:
            if req.device not in self._devices:
                raise RequestError("unknown_device", f"{self.name} has no device {req.device}")
            raise RequestError(
                "unknown_function", f"{req.device} has no function {req.function}")
        if not fn.params and not req.params:
            return fn, []
        try:
            values = convert_all(fn.params, req.params)
        except BadParam:
            raise RequestError("bad_params", signature(fn.name, fn.params)) from None
        return fn, values

    # -- get ----------------------------------------------------------------------------------
    def _get(self) -> list[Response]:
        """Every row as values; a reading MCP cannot carry (NaN: a sensor not heard from,
        saturated) is an error for that row alone, so the rest still gets through."""
        out = []
        for p in self.properties:
            try:
                value = p.read()
            except Exception as exc:  # a plugin's bug costs this row, not the get
                out.append(self._read_failed(p, exc))
                continue
            if isinstance(value, float) and not math.isfinite(value):
                out.append(error_response(self.name, p.device, "fault",
                                          f"no reading for {p.device}.{p.name}"))
            else:
                out.append(Response(self.name, p.device, p.name, (value,)))
        return out

    def _read_failed(self, p: Property, exc: Exception) -> Response:
        """The error row of a property whose read raised; its traceback is logged once."""
        if (p.device, p.name) not in self._broken_reads:
            self._broken_reads.add((p.device, p.name))
            log.error("module %s: reading %s.%s raised (logged once; the row answers fault "
                      "while it raises, the other rows as usual)", self.name, p.device, p.name,
                      exc_info=exc)
        return error_response(self.name, p.device, "fault",
                              f"reading {p.device}.{p.name} raised {type(exc).__name__}")

    def rows(self) -> list[Response]:
        """The get rows as values (what a recorder samples); `get_line` is the same on the
        wire."""
        return self._get()

    def get_line(self, version: Version) -> bytes:
        """The get answer as it goes on the wire (the same rows as `_get`), rebuilt only when
        `version` moved on since the last one (see the module docstring)."""
        rows = self._rows
        if version == self._get_version and rows is not None and len(rows) == len(
                self.properties):
            return self._get_answer
        if rows is None or len(rows) != len(self.properties):
            rows = self._rows = [
                (f"{self.name}:{p.device}.{p.name}=(", p.read,
                 format_response(error_response(self.name, p.device, "fault",
                                                f"no reading for {p.device}.{p.name}")))
                for p in self.properties]
        parts = []
        for row in rows:
            prefix, read, unreadable = row
            try:
                value = read()
            except Exception as exc:  # a plugin's bug costs this row, not the get
                failed = self._read_failed(self.properties[rows.index(row)], exc)
                parts.append(format_response(failed))
                continue
            if type(value) is int:
                parts.append(f"{prefix}{value})")
            elif isinstance(value, float) and not math.isfinite(value):
                parts.append(unreadable)
            else:
                parts.append(f"{prefix}{format_value(value)})")
        line = "".join(parts).encode("ascii")
        self._get_version, self._get_answer = version, line
        return line

    def _stop_request(self) -> None:
        self.stop()

    # -- describe -----------------------------------------------------------------------------
    def describe(self) -> list[Response]:
        out = []
        for fn in self.functions.values():
            out.append(Response(self.name, fn.device, "function",
                                (fn.name, *(p.describe() for p in fn.params))))
        for p in self.properties:
            vals: tuple[Value, ...] = (p.name, p.type, p.unit) if p.unit else (p.name, p.type)
            out.append(Response(self.name, p.device, "property", vals))
        out.extend(Response(self.name, fn.device, "kind", (fn.name, fn.kind))
                   for fn in self.functions.values())
        return out

    def describe_line(self, version: Version) -> bytes:
        """`describe` on the wire: the table does not change once built, so it is formatted
        once."""
        if self._describe is None:
            self._describe = answer(self.describe())
        return self._describe

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Attach: called when every bus the module uses is open. Start from rest."""
        self.stop()

    @abstractmethod
    def stop(self) -> None:
        """Every motor of the module to zero, any move cancelled."""

    @abstractmethod
    def is_moving(self) -> bool:
        """True while any motor is commanded non-zero or a move is in progress."""

    def tasks(self) -> list[Task]:
        """Periodic work; run only while the module is attached."""
        return []
