"""The `interlocks:` section of `ramp.yaml` (SPEC 11), checked with the rest of the file.

    interlocks:
      - name: chain_needs_ladder_down      # 1-32 of letters, digits, _ and -, unique
        when: "ble:lift.pos > 0.5"         # ramp.layers.robot_distribution.condition
        refuse: ["ble:chain.vel"]          # exactly one of refuse, stop, limit
        latch: false                       # optional
        severity: warning                  # optional: info, warning (default) or error
        message: "Lower the bin first"     # optional: the operator's advice

A `refuse` or `stop` entry is a pattern, or a map `{PATTERN: forward|reverse}` forbidding one
direction only. A name may not be `none` (what `interlock.active` reads with no rule active);
a message travels in MCP values, so it is printable ASCII without `,` `(` `)`; at most
`MAX_RULES` rules.

Every name a rule uses is checked against the module tables: a property must be a get row
of a module in `modules:`, a pattern must name at least one motion function, and a `limit`
pattern at least one with a speed (an int in % as its first parameter). The tables exist only
once a module is built, so each module a rule names is built here on inert channels (the sim
driver on an empty world: no port is opened, no device is touched), the same class `ramp run`
builds; a plugin's module is checked the same way. `ramp check` and `ramp run` share this
check, so a rule that names a missing device fails both with the same file:line:key.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from typing import Any

from ramp.common.yamlload import LinedList, LinedMap, kind_of
from ramp.hal.simio import SimBus
from ramp.layers.module_distribution import BoundDevice, Module
from ramp.layers.robot_distribution.condition import (
    ConditionError,
    Node,
    parse_condition,
    properties,
)
from ramp.layers.robot_distribution.interlocks import (
    ACTIONS,
    DIRECTIONS,
    MAX_RULES,
    PATTERN,
    PROPERTY,
    RESERVED_NAMES,
    RULE_NAME,
    SEVERITIES,
    RuleSpec,
    covered,
    find_property,
    motion_matches,
    speed_param,
)
from ramp.modules import module_class
from ramp.schema import shorten

KEYS = ("name", "when", "refuse", "stop", "limit", "latch", "severity", "message")
#: The longest `message:` (one line of advice in an alert).
MAX_MESSAGE = 200
_MESSAGE = re.compile(r"[\x20-\x27\x2a\x2b\x2d-\x7e]+\Z")

Err = Callable[[str, int, str], None]


class _NullWorld:
    """A simulated world with nothing in it: channels to build a module's table on."""

    def set_motor(self, name: str, duty: float) -> None:
        pass

    def read_analog(self, name: str) -> float:
        return 0.0

    def read_digital(self, name: str) -> bool:
        return False

    def write_digital(self, name: str, on: bool) -> None:
        pass

    def read_bridge(self, name: str) -> float:
        return 0.0

    def bus_present(self, bus: str) -> bool:
        return False


def module_table(name: str, mc: Any) -> Module:
    """Module `name` of config `mc` built on inert channels, for its functions and get rows
    (see the module docstring). Raises what the module's constructor raises."""
    bus = SimBus(f"{name}-table", {}, world=_NullWorld())
    devices = {dev: BoundDevice(bus.channel(dc.kind, f"{name}.{dev}", {}), dc.params)
               for dev, dc in mc.devices.items()}
    module: Module = module_class(mc.type)(name, devices, mc.settings)
    return module


class _Tables:
    """The modules' tables, each built once and only when a rule names it."""

    def __init__(self, modules: Mapping[str, Any]) -> None:
        self.configs = modules
        self.built: dict[str, Module | None] = {}
        self.errors: dict[str, str] = {}

    def get(self, name: str) -> Module | None:
        if name not in self.built:
            try:
                self.built[name] = module_table(name, self.configs[name])
            except Exception as exc:  # noqa: BLE001 - said as a config error, never a traceback
                self.errors[name] = shorten(str(exc) or type(exc).__name__, 200)
                self.built[name] = None
        return self.built[name]

    def all(self) -> dict[str, Module]:
        out = {}
        for name in self.configs:
            module = self.get(name)
            if module is not None:
                out[name] = module
        return out


def check_interlocks(raw: Any, line: int, modules: Mapping[str, Any], err: Err,
                     modules_ok: bool = True) -> tuple[RuleSpec, ...]:
    """The checked rules of the `interlocks:` value `raw` (at `line`), every problem given to
    `err(key, line, message)`. `modules` are the checked module configs; with
    `modules_ok` False (the modules section had errors) names are not checked against the
    tables, which could not be built."""
    if raw is None:
        return ()
    if not isinstance(raw, list):
        err("interlocks", line, f"expected a list of rules (- name: ..., when: ..., one of "
                                f"refuse/stop/limit), got {kind_of(raw)}")
        return ()
    if len(raw) > MAX_RULES:
        err("interlocks", line, f"{len(raw)} rules; at most {MAX_RULES} (every request and "
                                "tick may evaluate them: merge rules that share a condition)")
        return ()
    tables = _Tables(modules)
    out: list[RuleSpec] = []
    seen: dict[str, str] = {}
    for i, entry in enumerate(raw):
        path = f"interlocks[{i}]"
        if not isinstance(entry, LinedMap):
            err(path, _item_line(raw, i, line), "expected a rule (a mapping with name, when "
                f"and one of refuse, stop, limit), got {kind_of(entry)}")
            continue
        spec = _rule(entry, path, tables, err, modules_ok, seen)
        if spec is not None:
            out.append(spec)
    return tuple(out)


def _rule(entry: LinedMap, path: str, tables: _Tables, err: Err, modules_ok: bool,
          seen: dict[str, str]) -> RuleSpec | None:
    def at(key: str) -> int:
        return entry.lines.get(key, entry.line)

    ok = True
    for dup, dline in entry.duplicates:
        err(f"{path}.{dup}", dline, "key given twice")
        ok = False
    for key in entry:
        if key not in KEYS:
            err(f"{path}.{key}", at(key), f"unknown key (expected: {', '.join(KEYS)})")
            ok = False
    name = entry.get("name")
    if not isinstance(name, str) or not RULE_NAME.match(name):
        given = "missing" if name is None else f"{shorten(repr(name))} is not a rule name"
        err(f"{path}.name", at("name"), f"{given}; expected 1-32 letters, digits, _ or - (the "
                                        "name robot:interlock.reset=(NAME) takes)")
        ok = False
    elif name.lower() in RESERVED_NAMES:
        err(f"{path}.name", at("name"), f"{name} is reserved (robot:interlock.active=(none) "
                                        "says no rule is active); choose another name")
        ok = False
    elif name in seen:
        err(f"{path}.name", at("name"), f"{name} is already the name of {seen[name]}; names "
                                        "are unique")
        ok = False
    else:
        seen[name] = path
    when = _when(entry, path, at, tables, err, modules_ok)
    ok = ok and when is not None
    actions = [a for a in ACTIONS if a in entry]
    if len(actions) != 1:
        err(path, entry.line, "expected exactly one action: refuse: [PATTERN...], stop: "
                              "[PATTERN...] or limit: {PATTERN: N}" +
            (f" (given: {', '.join(actions)})" if actions else ""))
        return None
    action = actions[0]
    patterns = _patterns(entry[action], f"{path}.{action}", at(action), action, tables, err,
                         modules_ok)
    latch = entry.get("latch", False)
    if not isinstance(latch, bool):
        err(f"{path}.latch", at("latch"), f"{shorten(repr(latch))} is not true or false")
        ok = False
    severity = entry.get("severity", "warning")
    if severity not in SEVERITIES:
        err(f"{path}.severity", at("severity"), f"{shorten(repr(severity))} is not a "
            "severity; expected info (shapes normal work: shown, not an alert), warning "
            "(the default) or error")
        ok = False
    message = entry.get("message", "")
    if not isinstance(message, str):
        err(f"{path}.message", at("message"), f"expected the operator's advice as text, got "
                                              f"{kind_of(message)}")
        ok = False
    else:
        message = message.strip()
        if message and (len(message) > MAX_MESSAGE or not _MESSAGE.match(message)):
            err(f"{path}.message", at("message"),
                f"{shorten(repr(message), 60)}: a message is one line of at most "
                f"{MAX_MESSAGE} printable ASCII characters without , ( or ) (it travels in "
                "MCP values)")
            ok = False
    if not ok or when is None or patterns is None:
        return None
    assert isinstance(name, str)
    return RuleSpec(name, when, action, tuple((p, n) for p, n, _ in patterns), latch,
                    entry.line, str(severity), message,
                    tuple(d for _, _, d in patterns) if any(d for *_, d in patterns) else ())


def explain(rules: tuple[RuleSpec, ...], modules: Mapping[str, Any]) -> list[str]:
    """`ramp check --explain`: per rule, what it reads and every function each entry covers
    (the actuator, not the spelling: SPEC 11), as lines of text."""
    tables = _Tables(modules)
    built = tables.all()
    out: list[str] = []
    for spec in rules:
        extra = ", latched" if spec.latch else ""
        out.append(f"{spec.name} ({spec.severity}{extra}): {spec.action} while {spec.when}")
        if spec.message:
            out.append(f"  message: {spec.message}")
        directions = spec.directions or (0,) * len(spec.patterns)
        for (pattern, n), d in zip(spec.patterns, directions, strict=True):
            functions, _ = covered(pattern, built)
            how = (f" to {n} %" if n is not None else "") + (
                " (forward only)" if d > 0 else " (reverse only)" if d < 0 else "")
            names = ", ".join(f"{m}:{f.device}.{f.name}" for m, f in functions)
            out.append(f"  {pattern}{how} covers {names or 'nothing'}")
    return out


def _item_line(items: Any, i: int, default: int) -> int:
    """The line of item `i` of a YAML list (its own line in block style)."""
    if isinstance(items, LinedList) and i < len(items.lines):
        return items.lines[i]
    return default


def _when(entry: LinedMap, path: str, at: Callable[[str], int], tables: _Tables, err: Err,
          modules_ok: bool) -> Node | None:
    text = entry.get("when")
    key = f"{path}.when"
    if not isinstance(text, str):
        err(key, at("when"), "missing; expected a condition such as \"ble:lift.pos < 0.2\""
            if text is None else f"expected a condition as text (quote it), got {kind_of(text)}")
        return None
    try:
        node = parse_condition(text)
    except ConditionError as exc:
        err(key, at("when"), f"{exc} in {shorten(repr(text), 80)}")
        return None
    if not modules_ok:
        return node
    good = True
    for prop in properties(node):
        problem = _property_problem(prop, tables)
        if problem:
            err(key, at("when"), problem)
            good = False
    return node if good else None


def _property_problem(prop: str, tables: _Tables) -> str:
    m = PROPERTY.match(prop)
    assert m is not None  # the grammar only makes properties of this shape
    mod, dev, name = m.groups()
    if mod not in tables.configs:
        return (f"{prop}: no module {mod} (modules: {', '.join(tables.configs) or 'none'}); "
                "a condition reads a get property MODULE:DEVICE.PROPERTY")
    module = tables.get(mod)
    if module is None:
        return f"{prop}: module {mod} could not be built to read its table: {tables.errors[mod]}"
    if find_property(module, dev, name) is not None:
        return ""
    devices = sorted({p.device for p in module.properties})
    if dev not in devices:
        return f"{prop}: module {mod} has no get property on a device {dev} (devices: " \
               f"{', '.join(devices)})"
    rows = sorted(p.name for p in module.properties if p.device == dev)
    return f"{prop}: {mod}:{dev} has no property {name} (it has: {', '.join(rows)})"


def _patterns(raw: Any, key: str, line: int, action: str, tables: _Tables, err: Err,
              modules_ok: bool) -> tuple[tuple[str, int | None, int], ...] | None:
    """(pattern, limit or None, direction: 0, +1 forward or -1 reverse) per entry."""
    items: list[tuple[Any, Any]]
    if action != "limit" and isinstance(raw, dict) and raw:  # {PATTERN: forward|reverse}
        raw_map = raw
        raw = LinedList(line)
        for p, d in raw_map.items():
            entry = LinedMap(raw_map.line_of(p) if isinstance(raw_map, LinedMap) else line)
            entry[p] = d
            raw.append(entry)
            raw.lines.append(entry.line)
    if action == "limit":
        if not isinstance(raw, dict) or not raw:
            err(key, line, f"expected a mapping of patterns to a speed limit in % "
                           f"({{\"base:base.drive\": 30}}), got {kind_of(raw)}")
            return None
        items = list(raw.items())
    else:
        if isinstance(raw, str):
            raw = [raw]
        if not isinstance(raw, list) or not raw:
            err(key, line, f"expected a list of patterns MODULE:DEVICE.FUNCTION "
                           f"([\"ble:chain.vel\"], an entry may be {{PATTERN: forward}}), got "
                           f"{'an empty list' if raw == [] else kind_of(raw)}")
            return None
        items = [(p, None) for p in raw]
    out: list[tuple[str, int | None, int]] = []
    ok = True
    for i, (pattern, n) in enumerate(items):
        here = raw.line_of(pattern) if isinstance(raw, LinedMap) else _item_line(raw, i, line)
        direction = 0
        if action != "limit" and isinstance(pattern, dict):
            if len(pattern) != 1 or next(iter(pattern.values())) not in DIRECTIONS:
                err(key, here, f"{shorten(repr(dict(pattern)))}: a one-direction entry is "
                               "{PATTERN: forward} or {PATTERN: reverse}")
                ok = False
                continue
            pattern, way = next(iter(pattern.items()))
            direction = DIRECTIONS[way]
        if action == "limit" and (not isinstance(n, int) or isinstance(n, bool)
                                  or not 0 <= n <= 100):
            err(key, here,
                f"{shorten(repr(n))} is not a speed limit; expected an integer % in 0-100")
            ok = False
            continue
        problem = _pattern_problem(pattern, action, tables) if modules_ok else (
            "" if isinstance(pattern, str) and PATTERN.match(pattern) else "bad pattern")
        if problem:
            err(key, here, problem)
            ok = False
            continue
        out.append((pattern, n, direction))
    return tuple(out) if ok else None


def _pattern_problem(pattern: Any, action: str, tables: _Tables) -> str:
    if not isinstance(pattern, str) or not PATTERN.match(pattern):
        return (f"{shorten(repr(pattern))} is not a pattern; expected MODULE:DEVICE.FUNCTION, "
                "names of letters, digits and _ with * standing for any part of one "
                "(base:*_wheel.vel), or MODULE:* for all of a module's motion")
    m = PATTERN.match(pattern)
    assert m is not None
    mod, dev, fn = m.group(1), m.group(2) or "*", m.group(3) or "*"
    modules = tables.all()
    broken = [f"{m}: {e}" for m, e in tables.errors.items()]
    if broken:
        return f"{pattern}: a module could not be built to read its table ({broken[0]})"
    matches = motion_matches(pattern, modules)
    if not matches:
        return f"{pattern}: {_why_nothing(mod, dev, fn, modules)}"
    if action == "limit":
        speeds = [f for _, f in matches if speed_param(f) is not None]
        if not speeds:
            names = ", ".join(f"{m}:{f.device}.{f.name}" for m, f in matches)
            subject = pattern if names == pattern else f"{pattern} ({names})"
            return (f"{subject} has no speed to limit (its first parameter is not an int in "
                    "%); use refuse or stop for it")
    return ""


def _why_nothing(mod: str, dev: str, fn: str, modules: Mapping[str, Module]) -> str:
    import fnmatch

    mods = [m for m in modules if fnmatch.fnmatchcase(m, mod)]
    if not mods:
        return f"no module {mod} (modules: {', '.join(modules) or 'none'})"
    motion = [(m, f) for m in mods for f in modules[m].functions.values() if f.kind == "motion"]
    devs = sorted({f.device for _, f in motion})
    if not any(fnmatch.fnmatchcase(f.device, dev) for _, f in motion):
        known = sorted({f.device for m in mods for f in modules[m].functions.values()})
        if any(fnmatch.fnmatchcase(d, dev) for d in known):
            return f"no motion function on {mod}:{dev} (motion devices: {', '.join(devs)})"
        return f"no device {dev} in {mod} (devices with motion: {', '.join(devs)})"
    names = sorted({f"{f.device}.{f.name}" for _, f in motion
                    if fnmatch.fnmatchcase(f.device, dev)})
    known_fns = sorted({f.name for m in mods for f in modules[m].functions.values()
                        if fnmatch.fnmatchcase(f.device, dev)})
    if any(fnmatch.fnmatchcase(n, fn) for n in known_fns):
        return f"{fn} is not a motion function (interlocks guard motion: {', '.join(names)})"
    return f"no function {fn} (motion functions there: {', '.join(names)})"

