"""Interlocks (SPEC 11): one module's state restricting another's motion, declared as data.

A rule is a condition over get properties (`ramp.layers.robot_distribution.condition`) and one
action on motion functions named by patterns (`MODULE:DEVICE.FUNCTION`, `*` within a name):

- `refuse`: matching motion requests answer `interlocked`; the matching devices stop when the
  rule becomes active (a permit checked at the start of a command, PLC practice);
- `stop`: the same, said as what it is for (a protect: stop now, no new motion);
- `limit N`: the speed of matching motion (a function's first parameter, an int in %) is
  clamped to +-N, and motion already faster is brought down each tick. A matching motion
  function without a speed (`lift.pos`, `lift.extend`) is refused while the limit holds: it
  would run at a speed the rule forbids. `ramp.config` refuses a limit pattern that names
  only such functions.

**What a rule covers: the actuator, not the spelling.** A pattern names motion functions;
the rule covers every device those functions move, and so every motion function that moves
one of those devices: `ble:lift.vel` covers `lift.extend`, `lift.retract` and `lift.pos`;
`base:lf_wheel.vel` covers `base.drive`, which moves that wheel; `base:base.drive` covers
the four `wheel.vel`. A function's devices are its `Function.moves` (a module-level function
that declares none moves every device of its module that has motion: the safe guess), else
its own device. `covered` works this out once, for the running rules and `ramp check
--explain` alike.

**Direction.** A `refuse` or `stop` entry may forbid one direction only (`{"base:*":
forward}`): a request is refused when it would run a covered device that way, as the
function's `Function.senses` tells (the sign of the speed for a one-device speed function;
for `base.drive`, the sign of each wheel's share of the mix), and one whose direction
cannot be told is refused either way. When such a rule becomes active, a covered device
that runs that way (its speed reading's sign) is stopped; one running the other way keeps
running, so Scout can back away from a pressed bumper.

**When rules are evaluated.** Every tick, after the buses sampled their inputs and before any
module's own work (`tick`), and again for the rules guarding a motion request as it arrives
(`permit`), since a request earlier in the same message may have changed a reading (a
request skips the same rules a tick would, against the readings the last tick saw). A tick
reads each property the rules use once (however many rules read it) and evaluates only the
rules that are active, or released since the last tick, or have a comparison that the
change of a reading since the last tick may flip (a threshold between the old and the new
value): a rule that did not hold cannot hold while none of its comparisons changed. Its
cost is the reads and the rules a change touches; 480 rules over readings that wander
about without crossing a threshold (a noisy battery voltage) cost the reads alone. The
reads are the modules' own get properties (`Property.read`), the values a get answer is
formatted from, never a formatted answer.

**A limit never brings motion back.** A limit lowers motion that runs now: a speed read on
the device, or the last request of a module-level function (`base.drive`, whose direction
the limit keeps), which is forgotten at every stop (a module's stop, a robot-wide stop, a
takeover, a watchdog trip, a rule's stop) and is re-run only while the module is moving.

**Severity** (`info`, `warning`, `error`) and a rule's own `message` are published by
`describe` for the console. An `info` rule shapes normal work: its activations and releases
are logged at DEBUG (the flight recorder still records each; `ramp log summary` counts
them per rule).

**Release.** A rule becomes active in the tick (or request) its condition is seen true, and
is released once the condition has been clear for `RELEASE_AFTER_S` (0.1 s): a reading that
hovers at its threshold keeps the rule active instead of switching it 100 times a second
(each switch logged, recorded, and stopping devices). Being active longer is the safe side.

**Fail closed.** A rule whose property cannot be read (its module not `ok`, a reading MCP
cannot carry, a reader that raised) counts as active. A latching rule latches only on its
condition seen true: a module that is still attaching at boot, or is unplugged, holds its
rules active while it is unreadable, and they release once it reads clear again.

**Stopping a device** is the device's own speed function at 0 (`lift.vel=(0)` cancels a
position move too; `base.drive=(0,...)` stops every wheel), or, for a device with no speed
function, its module's `stop()`: the only stop every module has. Stops are never refused,
and neither is a speed function asked for 0 (`ble:chain.vel=(0)`), which is one.
"""

from __future__ import annotations

import bisect
import fnmatch
import logging
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from ramp.layers.module_distribution import Function, Module, Property
from ramp.layers.robot_distribution.condition import (
    Node,
    comparisons,
    compile_condition,
    properties,
)
from ramp.mcp.params import FlagParam, FloatParam, IntParam, Param

log = logging.getLogger("ramp.interlock")

Action = Literal["refuse", "stop", "limit"]
ACTIONS: tuple[Action, ...] = ("refuse", "stop", "limit")
#: A rule's name: what `robot:interlock.reset=(NAME)` and the error answers carry.
RULE_NAME = re.compile(r"[A-Za-z0-9_-]{1,32}\Z")
#: `MODULE:DEVICE.FUNCTION`, or `MODULE:*` for every motion function of a module.
PATTERN = re.compile(
    r"([A-Za-z0-9_*]{1,32}):(?:([A-Za-z0-9_*]{1,32})\.([A-Za-z0-9_*]{1,32})|\*)\Z")
PROPERTY = re.compile(r"([A-Za-z0-9_]{1,32}):([A-Za-z0-9_]{1,32})\.([A-Za-z0-9_]{1,32})\Z")
#: Names a rule may not take: `robot:interlock.active=(none)` means no rule is active.
RESERVED_NAMES = ("none",)
SEVERITIES = ("info", "warning", "error")
#: `{PATTERN: forward|reverse}`: the sign of the motion a directional entry forbids.
DIRECTIONS = {"forward": 1, "reverse": -1}
#: The most rules a robot may have: far past any real robot's (MARTE has 4), a bound on
#: what one request and one tick can cost.
MAX_RULES = 1000

#: Observer hook: (rule name, active, why, clock time) at every activation and release.
InterlockHook = Callable[[str, bool, str, float], None]


@dataclass(frozen=True)
class RuleSpec:
    """One checked rule of `interlocks:` (made by `ramp.config`)."""

    name: str
    when: Node
    action: Action
    #: (pattern, N): N is the limit in % for `limit`, None for `refuse` and `stop`.
    patterns: tuple[tuple[str, int | None], ...]
    latch: bool = False
    line: int = 0
    severity: str = "warning"
    #: The operator's advice shown with the alert (no `,` `)` or line end: it travels in MCP
    #: values); "" when the rule has none.
    message: str = ""
    #: Per pattern: 0 any motion, +1 forward only, -1 reverse only (`refuse`/`stop` maps);
    #: empty: all 0.
    directions: tuple[int, ...] = ()


# -- what the tables offer (shared with the config check) -----------------------------------

def speed_param(fn: Function) -> IntParam | None:
    """The speed of a motion function: its first parameter when that is an int in % that
    includes 0 (`vel=(int -100..100)`, `drive=(int -100..100,float)`); else None."""
    if fn.kind != "motion" or not fn.params:
        return None
    p = fn.params[0]
    if isinstance(p, IntParam) and -100 <= p.lo <= 0 <= p.hi <= 100 and p.lo < p.hi:
        return p
    return None


def motion_matches(pattern: str, modules: Mapping[str, Module]) -> list[tuple[str, Function]]:
    """Every (module name, motion function) the pattern names, in table order."""
    m = PATTERN.match(pattern)
    if m is None:
        return []
    mp, dp, fp = m.group(1), m.group(2) or "*", m.group(3) or "*"
    out: list[tuple[str, Function]] = []
    for name, module in modules.items():
        if not fnmatch.fnmatchcase(name, mp):
            continue
        out.extend((name, fn) for fn in module.functions.values()
                   if fn.kind == "motion" and fnmatch.fnmatchcase(fn.device, dp)
                   and fnmatch.fnmatchcase(fn.name, fp))
    return out


def moved_devices(module: Module, fn: Function) -> tuple[str, ...]:
    """The devices a motion function moves (see the module docstring)."""
    if fn.moves:
        return fn.moves
    if fn.device != module.name:
        return (fn.device,)
    others = sorted({f.device for f in module.functions.values()
                     if f.kind == "motion" and f.device != module.name})
    return tuple(others) or (fn.device,)


def covered(pattern: str, modules: Mapping[str, Module]
            ) -> tuple[list[tuple[str, Function]], dict[str, tuple[str, ...]]]:
    """What a pattern covers: every (module, motion function) that moves a device some
    function the pattern names moves, in table order, and per module those devices."""
    devices: dict[str, dict[str, None]] = {}
    for mod, fn in motion_matches(pattern, modules):
        devices.setdefault(mod, {}).update(dict.fromkeys(moved_devices(modules[mod], fn)))
    out: list[tuple[str, Function]] = []
    for mod, devs in devices.items():
        out.extend((mod, fn) for fn in modules[mod].functions.values()
                   if fn.kind == "motion" and any(d in devs for d in
                                                  moved_devices(modules[mod], fn)))
    return out, {mod: tuple(devs) for mod, devs in devices.items()}


def senses_of(module: Module, fn: Function, values: Sequence[Any]) -> Sequence[int] | None:
    """Which way each device of `moved_devices(module, fn)` would run for `values` (+1, -1,
    0), or None when that cannot be told (the rule then refuses either way)."""
    if fn.senses is not None:
        try:
            got = fn.senses(*values)
        except Exception:  # plugin code: a direction we cannot tell
            return None
        if got is None or len(got) != len(moved_devices(module, fn)):
            return None
        return got
    if speed_param(fn) is not None and len(moved_devices(module, fn)) == 1:
        v = values[0]
        return ((v > 0) - (v < 0),)
    return None


def find_property(module: Module, device: str, name: str) -> Property | None:
    for p in module.properties:
        if p.device == device and p.name == name:
            return p
    return None


def _neutral(p: Param) -> Any:
    """A value of `p` that asks for no motion, for the parameters after a zero speed."""
    if isinstance(p, IntParam):
        return min(max(0, p.lo), p.hi)
    if isinstance(p, FloatParam):
        lo = -math.inf if p.lo is None else p.lo
        hi = math.inf if p.hi is None else p.hi
        return min(max(0.0, lo), hi)
    if isinstance(p, FlagParam):
        return 0
    raise ValueError(f"no neutral value for {p.describe()}")


# -- the running rules ----------------------------------------------------------------------

#: What a guard does to a request while its rule is active: refuse it, refuse it unless its
#: speed is 0 (a stop), clamp its speed, or refuse it when it runs a device one way.
REFUSE, ZERO_ONLY, LIMIT, DIRECTION = 0, 1, 2, 3
#: A rule is released once its condition has been clear this long (s): ten ticks at 100 Hz.
RELEASE_AFTER_S = 0.1
#: `Rule.evaluate`'s answers besides an unreadable property's index.
HOLDS, CLEAR = -1, -2
#: What a refusal says of a latched rule whose condition has cleared.
LATCHED = "is latched until robot:interlock.reset"
#: A value no reading is: every property counts as changed at the first tick.
_UNSEEN: Any = object()


@dataclass
class _Limit:
    """One speed function a limit rule holds to +-n."""

    slot: Any  # ModuleSlot (not imported: the registry imports this layer's siblings)
    fn: Function
    lo: int
    hi: int
    #: The device's get row of the same name (`lift.vel` for `lift.vel`), for a function of
    #: one parameter: what the device runs at now.
    reading: Callable[[], Any] | None


@dataclass
class _Stop:
    """One device a refuse/stop rule stops when it becomes active."""

    slot: Any
    device: str
    #: 0: stop it; +1/-1: stop it only while its `reading` says it runs that way.
    sign: int
    reading: Callable[[], Any] | None


@dataclass(frozen=True)
class _Guard:
    """What one rule does to requests of one function."""

    rule: Rule
    effect: int
    lo: int = 0
    hi: int = 0
    #: DIRECTION: the sign forbidden, and the indices (in `moved_devices`) of the covered
    #: devices it is forbidden on.
    sign: int = 0
    which: tuple[int, ...] = ()


class Rule:
    """One rule as it runs: its reads, its predicate, its state and what it acts on."""

    def __init__(self, spec: RuleSpec, index: tuple[int, ...],
                 predicate: Callable[[Sequence[float]], bool], order: int) -> None:
        self.spec = spec
        self.name = spec.name
        self.order = order
        #: Where the rule's properties sit in `Interlocks.values`.
        self.index = index
        self.predicate = predicate
        self.active = False
        self.latched = False
        #: The condition was seen true (not only unreadable) since the rule last became active.
        self.seen_true = False
        self.why = ""
        #: Clock time since which the condition has been clear (None while it holds).
        self.clear_since: float | None = None
        self.stops: list[_Stop] = []
        self.limits: list[_Limit] = []
        #: Every function the rule guards (a limit leaves motion of other functions alone).
        self.functions: set[int] = set()
        #: Times the rule became active (for a summary line: an `info` rule logs at DEBUG).
        self.activations = 0
        #: Times the predicate ran (the tick skips rules whose readings did not change).
        self.evaluations = 0

    def evaluate(self, values: list[Any]) -> int:
        """HOLDS, CLEAR, or the index of a property that cannot be read (fail closed: the
        rule holds), from the values read last (`Interlocks.read`)."""
        for i in self.index:
            if values[i] is None:
                return i
        self.evaluations += 1
        return HOLDS if self.predicate(values) else CLEAR

    def refusal(self) -> str:
        return f"{self.name} {self.why}"


class Interlocks:
    """Every rule of a robot, bound to its modules' tables (see the module docstring)."""

    def __init__(self, specs: Sequence[RuleSpec], slots: Mapping[str, Any]) -> None:
        self.slots = slots
        self.rules: list[Rule] = []
        self.by_name: dict[str, Rule] = {}
        #: Every property a rule reads, once: (name, slot, reader), and the values read last
        #: (None: unreadable). A tick reads each once, however many rules use it.
        self.props: list[tuple[str, Any, Callable[[], Any]]] = []
        self.values: list[Any] = []
        #: The values the last tick evaluated its rules on, and per property the rules
        #: reading it: a tick evaluates only what a change touches.
        self._ticked: list[Any] = []
        self._readers: list[list[Rule]] = []
        #: Per property: its rules' thresholds, sorted, with the rules comparing against
        #: each, and the `==`/`!=` ones by value: a change of reading touches only the rules
        #: whose comparisons it can flip (`_crossed`).
        self._thresholds: list[tuple[list[float], list[list[Rule]], dict[float, list[Rule]]]]
        self._thresholds = []
        #: Rules released outside a tick (by a request or a reset): evaluated at the next.
        self._recheck: dict[int, Rule] = {}
        #: Counts every latch and reset of a rule (the latch state file follows it).
        self.latch_changes = 0
        self._prop_index: dict[str, int] = {}
        #: Per guarded function: the properties its rules read.
        self._guard_props: dict[tuple[str, str, str], tuple[int, ...]] = {}
        #: (module, device, function) -> what each rule covering it does
        self.guards: dict[tuple[str, str, str], list[_Guard]] = {}
        #: Rules active now, by `Rule.order` (evaluated every tick: release timing, limits).
        self._active: dict[int, Rule] = {}
        #: Per module with a limit: the last motion function per device, and the last motion
        #: request's parameters (valid until a stop or another request on the module), see
        #: `ran` and `forget`.
        self._last_fn: dict[str, dict[str, Function]] = {}
        self._last_args: dict[str, tuple[Function, list[Any]] | None] = {}
        self._zero: dict[tuple[str, str], tuple[Function, tuple[Any, ...]] | None] = {}
        #: Observer hook (the flight recorder): None costs nothing.
        self.on_change: InterlockHook | None = None
        #: Called after rules stopped or slowed motion outside a request (the robot layer
        #: moves its state's version and disarms an idle watchdog).
        self.on_motion_changed: Callable[[float], None] | None = None
        modules = {name: slot.module for name, slot in slots.items()}
        for spec in specs:
            self._bind(spec, modules)
        for key, guards in self.guards.items():
            self._guard_props[key] = tuple(sorted({i for g in guards for i in g.rule.index}))
        self._all = tuple(range(len(self.props)))
        self._ticked = [_UNSEEN] * len(self.props)
        self._readers = [[] for _ in self.props]
        ordered: list[dict[float, list[Rule]]] = [{} for _ in self.props]
        equal: list[dict[float, list[Rule]]] = [{} for _ in self.props]
        for rule in self.rules:
            for i in set(rule.index):
                self._readers[i].append(rule)
            for cmp in comparisons(rule.spec.when):
                by = equal if cmp.op in ("==", "!=") else ordered
                group = by[self._prop_index[cmp.prop]].setdefault(cmp.value, [])
                if rule not in group:
                    group.append(rule)
        for i in range(len(self.props)):
            keys = sorted(ordered[i])
            self._thresholds.append((keys, [ordered[i][k] for k in keys], equal[i]))
        self._remembering = [(name, slot) for name, slot in slots.items()
                             if name in self._last_args]

    def _bind(self, spec: RuleSpec, modules: Mapping[str, Module]) -> None:
        for prop in properties(spec.when):
            if prop in self._prop_index:
                continue
            m = PROPERTY.match(prop)
            module = modules.get(m.group(1)) if m else None
            p = find_property(module, m.group(2), m.group(3)) if m and module else None
            if m is None or module is None or p is None:  # the config check prevents this
                raise ValueError(f"interlock {spec.name}: no property {prop}")
            self._prop_index[prop] = len(self.props)
            self.props.append((prop, self.slots[m.group(1)], p.read))
            self.values.append(None)
        index = self._prop_index
        rule = Rule(spec, tuple(index[p] for p in properties(spec.when)),
                    compile_condition(spec.when, index), len(self.rules))
        stop_devices: dict[tuple[str, str], int] = {}
        directions = spec.directions or (0,) * len(spec.patterns)
        for (pattern, n), sign in zip(spec.patterns, directions, strict=True):
            functions, devices = covered(pattern, modules)
            for mod, fn in functions:
                rule.functions.add(id(fn))
                key = (mod, fn.device, fn.name)
                sp = speed_param(fn) if spec.action == "limit" else None
                if spec.action == "limit" and sp is not None:
                    assert n is not None
                    lo, hi = max(sp.lo, -n), min(sp.hi, n)
                    guards = self.guards.setdefault(key, [])
                    mine = [k for k, g in enumerate(guards) if g.rule is rule]
                    if mine:  # covered by two of the rule's entries: the tighter holds
                        g = guards[mine[0]]
                        guards[mine[0]] = _Guard(rule, LIMIT, max(lo, g.lo), min(hi, g.hi))
                        for lim in rule.limits:
                            if lim.fn is fn:
                                lim.lo, lim.hi = max(lo, lim.lo), min(hi, lim.hi)
                        continue
                    guards.append(_Guard(rule, LIMIT, lo, hi))
                    reading = None
                    if len(fn.params) == 1:
                        prop_row = find_property(modules[mod], fn.device, fn.name)
                        reading = prop_row.read if prop_row is not None else None
                    rule.limits.append(_Limit(self.slots[mod], fn, lo, hi, reading))
                    self._last_fn.setdefault(mod, {})
                    self._last_args.setdefault(mod, None)
                elif sign:
                    moved = moved_devices(modules[mod], fn)
                    which = tuple(k for k, d in enumerate(moved) if d in devices[mod])
                    self.guards.setdefault(key, []).append(
                        _Guard(rule, DIRECTION, sign=sign, which=which))
                else:
                    # A zero speed is a stop, and stops are never refused.
                    effect = ZERO_ONLY if speed_param(fn) is not None else REFUSE
                    guards = self.guards.setdefault(key, [])
                    if not any(g.rule is rule and g.effect == effect for g in guards):
                        guards.append(_Guard(rule, effect))
            if spec.action != "limit":
                for mod, devs in devices.items():
                    for device in devs:
                        # Any entry stopping a device outright wins over a directional one.
                        k = (mod, device)
                        stop_devices[k] = 0 if stop_devices.get(k, sign) == 0 else sign
        # A module-level function re-run by a limit goes first: it keeps its direction.
        rule.limits.sort(key=lambda lim: lim.reading is not None)
        for (mod, device), sign in stop_devices.items():
            zero = _zero_of(modules[mod], device)
            self._zero.setdefault((mod, device), zero)
            reading = None
            if sign and zero is not None:
                row = find_property(modules[mod], device, zero[0].name)
                reading = row.read if row is not None else None
            rule.stops.append(_Stop(self.slots[mod], device, sign, reading))
        self.rules.append(rule)
        self.by_name[rule.name] = rule

    # -- the tick -----------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        """Scheduler task, before module work: the rules whose readings changed (and the
        active ones) evaluated, limits enforced."""
        for name, slot in self._remembering:  # before the rules: a limit reads it
            if self._last_args[name] is not None and not _moving(slot):
                self._last_args[name] = None
        self.read(self._all)
        values, ticked = self.values, self._ticked
        todo = dict(self._active)
        if self._recheck:
            todo.update(self._recheck)
            self._recheck.clear()
        for i, v in enumerate(values):
            old = ticked[i]
            if v != old:
                ticked[i] = v
                for rule in self._crossed(i, old, v):
                    todo[rule.order] = rule
        changed = False
        for order in sorted(todo) if len(todo) > 1 else todo:
            rule = todo[order]
            verdict = rule.evaluate(values)
            if verdict == CLEAR and not rule.active:
                continue  # the common case: nothing to do
            changed |= self.apply(rule, verdict, now)
            if rule.active and rule.limits:
                changed |= self._bring_down(rule)
        if changed and self.on_motion_changed is not None:
            self.on_motion_changed(now)

    def _crossed(self, i: int, old: Any, new: Any) -> list[Rule]:
        """The rules with a comparison of property `i` that a change from `old` to `new` may
        flip: a threshold between the two (both ends included), or an `==`/`!=` value equal
        to either. Every rule reading it when either is not a number (unread, unseen)."""
        if old is None or new is None or old is _UNSEEN:
            return self._readers[i]
        keys, groups, equal = self._thresholds[i]
        lo, hi = (old, new) if old < new else (new, old)
        out: list[Rule] = []
        for k in range(bisect.bisect_left(keys, lo), bisect.bisect_right(keys, hi)):
            out.extend(groups[k])
        if equal:
            out.extend(equal.get(old, ()))
            out.extend(equal.get(new, ()))
        return out

    def read(self, indices: Sequence[int]) -> None:
        """Read the properties at `indices` now: None for one that cannot be read (its
        module not `ok`, a reading that is not a finite number, a reader that raised)."""
        values, props = self.values, self.props
        for i in indices:
            _, slot, read = props[i]
            if slot.state != "ok":
                values[i] = None
                continue
            try:
                v = read()
                if v - v != 0:  # NaN or infinite
                    v = None
            except Exception:  # a reader that raised is a reading we do not have
                v = None
            values[i] = v

    def update(self, rule: Rule, now: float) -> bool:
        """Evaluate one rule on the values read last and `apply` the verdict."""
        return self.apply(rule, rule.evaluate(self.values), now)

    def apply(self, rule: Rule, verdict: int, now: float) -> bool:
        """A rule's verdict: on a change, log it, tell the observer and act. True when
        devices were told to stop."""
        holds = verdict != CLEAR
        unreadable = self.props[verdict][0] if verdict >= 0 else ""
        if holds:
            rule.clear_since = None
            if not unreadable:
                rule.seen_true = True
                if rule.spec.latch and not rule.latched:
                    rule.latched = True
                    self.latch_changes += 1
        elif rule.clear_since is None:
            rule.clear_since = now
        # Released only once clear for RELEASE_AFTER_S: a reading hovering at the threshold
        # (a lift held at 0.5 against `> 0.5`) keeps the rule active instead of flapping. A
        # rule held only because a property could not be read (a module still attaching at
        # boot) is released as soon as the reading is there and clear.
        active = holds or rule.latched or (
            rule.active and rule.seen_true
            and now - rule.clear_since < RELEASE_AFTER_S)  # type: ignore[operator]
        was = rule.active
        rule.active = active
        if active:  # what a refusal says: why it is active now
            rule.why = (f"is active: {unreadable} cannot be read" if unreadable
                        else "is active" if holds or not rule.latched else LATCHED)
        if active == was:
            return False
        info = rule.spec.severity == "info"
        if not active:
            del self._active[rule.order]
            self._recheck[rule.order] = rule  # the next tick sees it on its own readings
            rule.why = ""
            rule.seen_true = False
            log.log(logging.DEBUG if info else logging.INFO, "interlock %s released",
                    rule.name)
            self._tell(rule, False, "released", now)
            return False
        self._active[rule.order] = rule
        rule.activations += 1
        if unreadable:
            what = f"active (fail closed): {unreadable} cannot be read"
        else:
            what = f"active: {rule.spec.when}"
            if rule.spec.latch:
                what += f" (latched until robot:interlock.reset=({rule.name}))"
        # An `info` rule is normal work (MARTE's digging creep): DEBUG, counted by the
        # recorder's summary. A limit engaging is the rule working as designed: a note. A
        # refusal, a stop or a latch, or any rule failing closed, is worth a warning.
        if unreadable:
            level = logging.WARNING if rule.spec.severity != "error" else logging.ERROR
        elif info:
            level = logging.DEBUG
        elif rule.spec.severity == "error":
            level = logging.ERROR
        elif rule.spec.action == "limit" and not rule.spec.latch:
            level = logging.INFO
        else:
            level = logging.WARNING
        log.log(level, "interlock %s %s", rule.name, what)
        self._tell(rule, True, what, now)
        return self._stop_devices(rule)

    def _tell(self, rule: Rule, active: bool, why: str, now: float) -> None:
        if self.on_change is not None:
            self.on_change(rule.name, active, why, now)

    def _stop_devices(self, rule: Rule) -> bool:
        stopped = False
        for stop in rule.stops:
            slot, device = stop.slot, stop.device
            if slot.state != "ok":
                continue  # its motion is already stopped
            if stop.sign and stop.reading is not None:
                try:
                    v = stop.reading()
                except Exception:
                    v = None
                if isinstance(v, int | float) and v == v and v * stop.sign <= 0:
                    continue  # still, or running the way the rule allows
            zero = self._zero.get((slot.name, device))
            self.forget(slot.name)
            try:
                if zero is not None:
                    zero[0].run(*zero[1])
                else:
                    slot.module.stop()
            except Exception:
                log.exception("interlock %s: stopping %s:%s failed; stopping module %s",
                              rule.name, slot.name, device, slot.name)
                try:
                    slot.module.stop()
                except Exception:
                    log.exception("module %s failed to stop", slot.name)
            stopped = True
        return stopped

    def _bring_down(self, rule: Rule) -> bool:
        """Motion of the rule's speed functions running now outside +-n: run at the limit.
        Never starts anything (see the module docstring)."""
        changed = False
        for lim in rule.limits:
            slot = lim.slot
            if slot.state != "ok":
                continue
            fn = lim.fn
            if lim.reading is not None:
                last = self._last_fn[slot.name].get(fn.device)
                if last is not None and id(last) not in rule.functions:
                    continue  # that motion comes from a function the rule leaves alone
                try:
                    v = lim.reading()
                except Exception:
                    continue
                if not isinstance(v, int | float) or v != v or lim.lo <= v <= lim.hi:
                    continue
                args: list[Any] = [int(min(max(v, lim.lo), lim.hi))]
            else:
                remembered = self._last_args.get(slot.name)
                if remembered is None or remembered[0] is not fn:
                    continue
                args = list(remembered[1])
                if lim.lo <= args[0] <= lim.hi:
                    continue
                if not _moving(slot):  # stopped by a path that did not tell us: nothing runs
                    self._last_args[slot.name] = None
                    continue
                args[0] = min(max(args[0], lim.lo), lim.hi)
            try:
                fn.run(*args)
            except Exception:
                log.exception("interlock %s: slowing %s:%s.%s failed; stopping module %s",
                              rule.name, slot.name, fn.device, fn.name, slot.name)
                self.forget(slot.name)
                slot.module.stop()
                continue
            log.log(logging.DEBUG if rule.spec.severity == "info" else logging.INFO,
                    "interlock %s: %s:%s.%s brought down to %s", rule.name, slot.name,
                    fn.device, fn.name, args[0])
            self.ran(slot.name, fn, args)
            changed = True
        return changed

    # -- the request path ---------------------------------------------------------------------
    def permit(self, module: str, fn: Function, values: list[Any], now: float) -> str | None:
        """A motion request that passed every other check: None to run it (a limit clamps
        `values[0]` in place), or why it is refused (`interlocked`)."""
        key = (module, fn.device, fn.name)
        guards = self.guards.get(key)
        if guards is None:
            return None
        props = self._guard_props[key]
        self.read(props)
        readings, ticked = self.values, self._ticked
        # An inactive rule the last tick left so, none of whose comparisons the readings
        # since can have flipped, still does not hold: only the others are evaluated.
        touched: set[int] | None = None
        for i in props:
            if readings[i] != ticked[i]:
                if touched is None:
                    touched = set(self._recheck)
                touched.update(r.order for r in self._crossed(i, ticked[i], readings[i]))
        if touched is None and self._recheck:
            touched = set(self._recheck)
        refusal = None
        stopped = False
        senses: Sequence[int] | None = None
        told = False  # `senses` worked out (once per request, when a guard needs it)
        for g in guards:
            rule = g.rule
            if not rule.active and (touched is None or rule.order not in touched):
                continue
            verdict = rule.evaluate(readings)
            if verdict != CLEAR or rule.active:
                stopped |= self.apply(rule, verdict, now)
            if not rule.active:
                continue
            effect = g.effect
            if effect == ZERO_ONLY:
                if refusal is None and values[0] != 0:
                    refusal = rule.refusal()
            elif effect == REFUSE:
                if refusal is None:
                    refusal = rule.refusal() if rule.spec.action != "limit" else (
                        f"{rule.name} limits {module}:{fn.device} and {fn.name} has no speed")
            elif effect == DIRECTION:
                if refusal is not None or (speed_param(fn) is not None and values[0] == 0):
                    continue  # a zero speed is a stop
                if not told:
                    senses, told = senses_of(self.slots[module].module, fn, values), True
                if senses is None or any(
                        senses[k] == g.sign for k in g.which):
                    way = "forward" if g.sign > 0 else "reverse"
                    refusal = f"{rule.refusal()} ({way} motion refused)"
            else:
                values[0] = min(max(values[0], g.lo), g.hi)
        if stopped and self.on_motion_changed is not None:
            self.on_motion_changed(now)
        return refusal

    def ran(self, module: str, fn: Function, values: Sequence[Any]) -> None:
        """An accepted motion or stop on `module` (only modules a limit watches keep this):
        the last function per device, and the last request's parameters."""
        last = self._last_fn.get(module)
        if last is None:
            if module == "robot" and fn.kind == "stop":
                self.stopped_all()
            return
        if fn.kind == "motion":
            last[fn.device] = fn
            self._last_args[module] = (fn, list(values))
        else:
            self.forget(module)

    def forget(self, module: str) -> None:
        """`module` stopped (all or part of it): no request of it is remembered as running,
        so a limit can never re-run it."""
        last = self._last_fn.get(module)
        if last is not None:
            last.clear()
            self._last_args[module] = None

    def stopped_all(self) -> None:
        """`robot.stop` and every other robot-wide stop (a takeover, a watchdog trip, a
        stall, a lost commander): nothing is remembered as running."""
        for module in self._last_fn:
            self.forget(module)

    def reset(self, name: str, now: float) -> str | None:
        """`robot:interlock.reset=(NAME)`: None when done (or nothing to do), else why not."""
        rule = self.by_name[name]
        if not rule.latched:
            return None
        self.read(rule.index)
        verdict = rule.evaluate(self.values)
        if verdict >= 0:
            return f"{name}: {self.props[verdict][0]} cannot be read; reset once it reads clear"
        if verdict == HOLDS:
            return f"{name}: its condition still holds; reset once it has cleared"
        rule.latched = False
        self.latch_changes += 1
        rule.clear_since = -math.inf  # acknowledged: released now
        log.info("interlock %s reset", name)
        self.update(rule, now)
        return None

    def restore_latched(self, names: Sequence[str]) -> list[str]:
        """Latch the latching rules in `names` (kept across a restart, SPEC 2.2): active from
        the next evaluation until reset. Returns the names this config has no latching rule
        for."""
        unknown = []
        for name in names:
            rule = self.by_name.get(name)
            if rule is None or not rule.spec.latch:
                unknown.append(name)
                continue
            if not rule.latched:
                rule.latched = True
                self.latch_changes += 1
            self._recheck[rule.order] = rule
        return unknown

    def latched_names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.rules if r.latched)

    def active_names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.rules if r.active)


def _moving(slot: Any) -> bool:
    """The slot's module is attached and moving; a module whose `is_moving` raises (plugin
    code) counts as still, so nothing it remembers is ever re-run."""
    try:
        return slot.state == "ok" and bool(slot.module.is_moving())
    except Exception:
        return False


def _zero_of(module: Module, device: str) -> tuple[Function, tuple[Any, ...]] | None:
    """How to stop one device: its speed function at 0 (one parameter preferred), else None
    (the module's stop)."""
    best = None
    for fn in module.functions.values():
        if fn.device != device or speed_param(fn) is None:
            continue
        try:
            rest = tuple(_neutral(p) for p in fn.params[1:])
        except ValueError:
            continue
        if best is None or len(fn.params) < len(best[0].params):
            best = (fn, (0, *rest))
    return best
