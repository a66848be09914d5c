"""Module distribution layer: a table-driven router.

Each module declares its functions and get properties once, as data. Validation, error
responses, `get` and `describe` all come from that one table, so they cannot drift apart.
The robot distribution layer does the checks that need the whole robot (module state,
ownership, watchdog); this layer finds the function and types the parameters.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from ramp.errors import RequestError
from ramp.mcp.messages import Request, Response, Value, error_response
from ramp.mcp.params import BadParam, Param, convert_all, signature
from ramp.schema import Field

#: motion: moves something (owner only, arms the watchdog); stop: accepted from anyone;
#: state: changes something that does not move (owner only); read: open to everyone;
#: control: arbitration itself (acquire is open to everyone, it is how a takeover happens).
Kind = Literal["motion", "stop", "state", "read", "control"]


@dataclass(frozen=True)
class Function:
    """One `device.function` a module accepts."""

    device: str
    name: str
    params: tuple[Param, ...]
    run: Callable[..., list[Response] | None]
    kind: Kind = "motion"
    help: str = ""


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
    fields: dict[str, Field] = field(default_factory=dict)
    help: str = ""


@dataclass(frozen=True)
class BoundDevice:
    """A YAML device after the supervisor built it: its HAL channel and its own keys."""

    channel: Any  # MotorChannel, AnalogInput, DigitalInput, DigitalOutput or BridgeInput
    params: Mapping[str, Any]  # values of DeviceSpec.fields, checked, defaults filled in


@dataclass(frozen=True)
class Task:
    """Periodic work a module asks the scheduler for."""

    name: str
    rate_hz: float
    run: Callable[[float, float], None]


class Module(ABC):
    """A module's distribution layer. Subclasses fill `functions` and `properties`.

    `get`, `stop` and `describe` on the module's own device are added here for every module.
    Concrete modules are built as `Cls(name, devices, settings)`: `devices` maps each name of
    `Cls.devices` to a `BoundDevice`, `settings` maps each block of `Cls.settings` to its
    checked values.
    """

    #: YAML: the hardware devices this module needs (name -> spec).
    devices: ClassVar[dict[str, DeviceSpec]] = {}
    #: YAML: extra settings blocks (block name -> keys), e.g. calibration.
    settings: ClassVar[dict[str, dict[str, Field]]] = {}

    def __init__(self, name: str) -> None:
        self.name = name
        self.functions: dict[tuple[str, str], Function] = {}
        self.properties: list[Property] = []
        self.add(Function(name, "get", (), self._get, "read", "every status row"))
        self.add(Function(name, "stop", (), self._stop_request, "stop", "stop all motion"))
        self.add(Function(name, "describe", (), self.describe, "read", "list functions"))

    # -- table --------------------------------------------------------------------------------
    def add(self, fn: Function) -> None:
        self.functions[(fn.device, fn.name)] = fn

    def prop(self, p: Property) -> None:
        self.properties.append(p)

    def lookup(self, req: Request) -> tuple[Function, list[Any]]:
        """The function a request names with its typed parameters, or RequestError."""
        fn = self.functions.get((req.device, req.function))
        if fn is None:
            if not any(dev == req.device for dev, _ in self.functions) and not any(
                    p.device == req.device for p in self.properties):
                raise RequestError("unknown_device", f"{self.name} has no device {req.device}")
            raise RequestError(
                "unknown_function", f"{req.device} has no function {req.function}")
        try:
            values = convert_all(fn.params, req.params)
        except BadParam:
            raise RequestError("bad_params", signature(fn.name, fn.params)) from None
        return fn, values

    def _get(self) -> list[Response]:
        """Every row; a reading MCP cannot carry (NaN: a sensor not heard from, saturated)
        answers an error for that row alone, so the rest of the message still gets through."""
        out = []
        for p in self.properties:
            value = p.read()
            if isinstance(value, float) and not math.isfinite(value):
                out.append(error_response(self.name, p.device, "fault",
                                          f"no reading for {p.device}.{p.name}"))
            else:
                out.append(Response(self.name, p.device, p.name, (value,)))
        return out

    def _stop_request(self) -> None:
        self.stop()

    def describe(self) -> list[Response]:
        out = []
        for fn in self.functions.values():
            out.append(Response(self.name, fn.device, "function",
                                (fn.name, *(p.describe() for p in fn.params))))
        for p in self.properties:
            vals: tuple[Value, ...] = (p.name, p.type, p.unit) if p.unit else (p.name, p.type)
            out.append(Response(self.name, p.device, "property", vals))
        return out

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


