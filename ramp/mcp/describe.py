"""What a robot offers, from its `describe` answers (SPEC 2.2): plain values, no I/O.

Every client builds its picture of the robot from these rows, never from tables of its own:
`ramp-shell` its completion and help, the teleop console its tree and panels. Rows that do
not fit the describe format are skipped rather than fatal: a newer robot may say more than a
client understands, and the rest is still worth showing.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from ramp.mcp.messages import Response, Value
from ramp.mcp.protocol import format_value

#: Functions that only read: `watch` re-polls these and nothing else, so it can never move
#: the robot, and `hold` refuses a message made of these alone.
READ_FUNCTIONS = frozenset({"get", "describe", "modules"})


@dataclass(frozen=True)
class FunctionInfo:
    """One request a module offers: `base:lf_wheel.vel` taking `int -100..100`."""

    module: str
    device: str
    name: str
    params: tuple[str, ...] = ()

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


@dataclass
class Catalog:
    """Everything `describe` said: modules, their functions and their get rows."""

    #: Known modules in the robot's order, `robot` first (it takes requests too).
    modules: list[str] = field(default_factory=list)
    functions: dict[str, list[FunctionInfo]] = field(default_factory=dict)
    properties: dict[str, list[PropertyInfo]] = field(default_factory=dict)
    #: Modules whose describe failed (e.g. `not_attached`), with the robot's reason.
    problems: dict[str, str] = field(default_factory=dict)

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
    _add_rows(cat, "robot", robot_rows)
    for module, rows in module_rows.items():
        if module not in cat.modules:
            cat.modules.append(module)
        _add_rows(cat, module, rows)
    return cat


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
        elif r.prop == "property":
            typ = values[1] if len(values) > 1 else ""
            unit = values[2] if len(values) > 2 else ""
            properties.append(PropertyInfo(module, r.device, values[0], typ, unit))
