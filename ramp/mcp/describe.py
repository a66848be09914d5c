"""What a robot offers, from its `describe` answers (SPEC 2.2): plain values, no I/O.

Every client builds its picture of the robot from these rows, never from tables of its own:
`ramp-shell` its completion and help, the teleop console its tree and panels. Rows that do
not fit the describe format are skipped rather than fatal: a newer robot may say more than a
client understands, and the rest is still worth showing.

Each function's kind comes from describe too (`MODULE:DEVICE.kind=(FUNCTION,KIND)`: `motion`,
`stop`, `state`, `read` or `control`), so a client knows what moves the robot without
guessing from names; `Catalog.kind_of` falls back to a guess only for a robot that does not
publish kinds.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

from ramp.mcp.messages import Response, Value
from ramp.mcp.protocol import format_value

#: Functions that only read, by name: the guess for a robot that does not publish kinds.
READ_FUNCTIONS = frozenset({"get", "describe", "modules"})
#: The kinds a robot publishes (SPEC 2.2 `describe`; docs/operating/mcp.md, "What a function
#: does").
KINDS = ("motion", "stop", "state", "read", "control")


def guess_kind(function: str) -> str:
    """A function's kind from its name alone (a robot that publishes no kinds): reads and
    stops are known by name; anything else may move the robot."""
    if function in READ_FUNCTIONS:
        return "read"
    return "stop" if function == "stop" else "motion"


@dataclass(frozen=True)
class FunctionInfo:
    """One request a module offers: `base:lf_wheel.vel` taking `int -100..100`."""

    module: str
    device: str
    name: str
    params: tuple[str, ...] = ()
    #: What it does, as describe says (`motion`, `stop`, `state`, `read`, `control`); ""
    #: when the robot did not say.
    kind: str = ""

    @property
    def hint(self) -> str:
        """`(int -100..100, float)`: what goes between the parentheses."""
        return f"({', '.join(self.params)})"

    @property
    def usage(self) -> str:
        """`base:base.drive=(int -100..100, float)`."""
        return f"{self.module}:{self.device}.{self.name}={self.hint}"


@dataclass(frozen=True)
class PropertyInfo:
    """One row a module's get answers: `base:battery.volt`, a float in V."""

    module: str
    device: str
    name: str
    type: str = ""
    unit: str = ""


#: An interlock rule's severities (SPEC 11); a robot that gives none means `warning`.
SEVERITIES = ("info", "warning", "error")


@dataclass(frozen=True)
class InterlockInfo:
    """One interlock rule as `robot:robot.describe` lists it: `robot:interlock.rule=(NAME,
    SEVERITY)` and, when the rule has one, `robot:interlock.message=(NAME,TEXT)`."""

    name: str
    severity: str = "warning"
    message: str = ""


@dataclass
class Catalog:
    """Everything `describe` said: modules, their functions and their get rows."""

    #: Known modules in the robot's order, `robot` first (it takes requests too).
    modules: list[str] = field(default_factory=list)
    functions: dict[str, list[FunctionInfo]] = field(default_factory=dict)
    properties: dict[str, list[PropertyInfo]] = field(default_factory=dict)
    #: Modules whose describe failed (e.g. `not_attached`), with the robot's reason.
    problems: dict[str, str] = field(default_factory=dict)
    #: The robot's interlock rules by name (from `robot:robot.describe`).
    interlocks: dict[str, InterlockInfo] = field(default_factory=dict)

    def devices(self, module: str) -> list[str]:
        """Devices of `module` that take requests, in describe order."""
        seen: dict[str, None] = {}
        for fn in self.functions.get(module, ()):
            seen.setdefault(fn.device)
        return list(seen)

    def functions_of(self, module: str, device: str) -> list[FunctionInfo]:
        return [fn for fn in self.functions.get(module, ()) if fn.device == device]

    def function(self, module: str, device: str, name: str) -> FunctionInfo | None:
        for fn in self.functions.get(module, ()):
            if fn.device == device and fn.name == name:
                return fn
        return None

    def kind_of(self, module: str, device: str, function: str) -> str:
        """What a request does, as describe said, or guessed from its name when the robot
        did not say (or the function is unknown)."""
        fn = self.function(module, device, function)
        if fn is not None and fn.kind:
            return fn.kind
        return guess_kind(function)

    def is_read(self, module: str, device: str, function: str) -> bool:
        return self.kind_of(module, device, function) == "read"

    def unit(self, module: str, device: str, prop: str) -> str:
        """The unit describe gave for a get row, or "" where there is none or it is unknown."""
        for p in self.properties.get(module, ()):
            if p.device == device and p.name == prop:
                return p.unit
        return ""


def value_text(v: Value) -> str:
    """A response value as MCP prints it."""
    return v if isinstance(v, str) else format_value(v)


def error_text(r: Response) -> str:
    """`bad_params: vel takes one int in -100..100` from an error response."""
    if not r.values:
        return "error"
    code, *rest = (value_text(v) for v in r.values)
    return f"{code}: {', '.join(rest)}" if rest else code


def build_catalog(robot_rows: Sequence[Response],
                  module_rows: Mapping[str, Sequence[Response]]) -> Catalog:
    """A catalog from `robot:robot.describe=()` and each `MODULE:MODULE.describe=()` answer.

    Rows that do not fit the describe format are skipped rather than fatal: a newer robot
    may say more than this client understands, and the rest is still worth completing.
    """
    cat = Catalog(modules=["robot"])
    for r in robot_rows:
        if r.prop == "error":
            cat.problems["robot"] = error_text(r)
        elif r.module == "robot" and r.device == "robot" and r.prop == "module" and r.values:
            name = value_text(r.values[0])
            if name not in cat.modules:
                cat.modules.append(name)
        elif r.module == "robot" and r.device == "interlock" and r.values:
            _add_interlock(cat, r.prop, [value_text(v) for v in r.values])
    _add_rows(cat, "robot", robot_rows)
    for module, rows in module_rows.items():
        if module not in cat.modules:
            cat.modules.append(module)
        _add_rows(cat, module, rows)
    return cat


def _add_interlock(cat: Catalog, prop: str, values: list[str]) -> None:
    """`rule=(NAME)` (an older robot), `rule=(NAME,SEVERITY)`, `message=(NAME,TEXT)`."""
    name, rest = values[0], values[1:]
    known = cat.interlocks.get(name, InterlockInfo(name))
    if prop == "rule":
        severity = rest[0] if rest and rest[0] in SEVERITIES else known.severity
        cat.interlocks[name] = replace(known, severity=severity)
    elif prop == "message" and rest:
        cat.interlocks[name] = replace(known, message=", ".join(rest))


def _add_rows(cat: Catalog, module: str, rows: Iterable[Response]) -> None:
    functions = cat.functions.setdefault(module, [])
    properties = cat.properties.setdefault(module, [])
    for r in rows:
        if r.module != module or not r.values:
            continue
        values = tuple(value_text(v) for v in r.values)
        if r.prop == "error":
            cat.problems[module] = error_text(r)
        elif r.prop == "function":
            info = FunctionInfo(module, r.device, values[0], values[1:])
            if info not in functions:
                functions.append(info)
        elif r.prop == "kind" and len(values) == 2 and values[1] in KINDS:
            for i, f in enumerate(functions):
                if f.device == r.device and f.name == values[0]:
                    functions[i] = replace(f, kind=values[1])
        elif r.prop == "property":
            typ = values[1] if len(values) > 1 else ""
            unit = values[2] if len(values) > 2 else ""
            properties.append(PropertyInfo(module, r.device, values[0], typ, unit))
