"""Gamepad and keyboard mapping profiles: YAML files checked on load, errors with file:line.

A profile binds inputs of a pad with the browser's `standard` mapping (buttons 0 A, 1 B, 2 X,
3 Y, 4 LB, 5 RB, 6 LT, 7 RT, 8 back, 9 start, 10/11 stick clicks, 12-15 D-pad up, down,
left, right, 16 home; axes 0/1 left stick, 2/3 right stick, up negative) to MCP requests.
Which requests exist is the robot's business (`describe`); a profile only names them, so a
binding to a request the robot does not offer is shown on the page, not refused here.

Profiles live in the package (`ramp/teleop/profiles/*.yaml`) and in the operator's config
directory (`$XDG_CONFIG_HOME/ramp/profiles/*.yaml`, default `~/.config/ramp/profiles/`);
an operator's file of the same name wins. The profile's name is its file name.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from ramp.common.yamlload import YamlError, compose, construct, read_text

#: The standard mapping's 17 buttons and 4 axes (W3C Gamepad, "Remapping").
BUTTON_COUNT = 17
AXIS_COUNT = 4
BUTTON_NAMES = ("A", "B", "X", "Y", "LB", "RB", "LT", "RT", "back", "start", "left stick",
                "right stick", "D-pad up", "D-pad down", "D-pad left", "D-pad right", "home")
AXIS_NAMES = ("left stick x", "left stick y", "right stick x", "right stick y")
#: The keys that drive in keyboard mode (held), and the turbo key.
DRIVE_KEYS = ("w", "a", "s", "d")
TURBO_KEY = "shift"

DEFAULT_PROFILE = "default"
_TARGET = re.compile(r"[A-Za-z0-9_]{1,32}:[A-Za-z0-9_]{1,32}\.[A-Za-z0-9_]{1,32}\Z")
_PARAM = re.compile(r"[A-Za-z0-9_.+\-]{1,64}\Z")
_NAME = re.compile(r"[A-Za-z0-9_.\-]{1,64}\Z")


class ProfileError(Exception):
    """A profile that cannot be used: `file:line: key.path: what was expected`."""

    def __init__(self, message: str, *, file: str = "", line: int = 0, key: str = "") -> None:
        self.file, self.line, self.key, self.detail = file, line, key, message
        where = f"{file}:{line}" if file and line else file
        super().__init__(": ".join(p for p in (where, key, message) if p))


# --------------------------------------------------------------------------- the profile


@dataclass(frozen=True)
class Input:
    """One pad input read as a number: an axis (-1..1) or a button's value (0..1)."""

    kind: str  # "axis" or "button"
    index: int
    invert: bool = False

    def read(self, axes: tuple[float, ...], buttons: tuple[float, ...]) -> float:
        values = axes if self.kind == "axis" else buttons
        v = values[self.index] if self.index < len(values) else 0.0
        v = v if math.isfinite(v) else 0.0
        return -v if self.invert else v

    def describe(self) -> str:
        names = AXIS_NAMES if self.kind == "axis" else BUTTON_NAMES
        name = names[self.index] if self.index < len(names) else f"{self.kind} {self.index}"
        return f"{'-' if self.invert else ''}{name} ({self.kind} {self.index})"


@dataclass(frozen=True)
class Binding:
    """Inputs to one request. Exactly one of `stick`, `value`, `press` says how.

    - stick: two inputs (forward, turn) to a drive request `(speed, direction)` in the
      convention of SPEC 2.3 (`base.drive`): speed -100..100, direction in degrees.
    - value: one input (minus another, if given) to a one-parameter request, -100..100.
    - press: a button that sends the request with `params` once each time it goes down.
    """

    request: str
    name: str
    stick: tuple[Input, Input] | None = None
    value: Input | None = None
    minus: Input | None = None
    press: int | None = None
    params: tuple[str, ...] = ()
    deadzone: float = 0.1
    expo: float = 0.0
    scale: float = 1.0
    turbo_scale: float = 1.0

    @property
    def module(self) -> str:
        return self.request.split(":", 1)[0]

    def describe(self) -> str:
        """`left stick y, left stick x -> base:base.drive` for the page's mapping table."""
        if self.stick is not None:
            what = f"{self.stick[0].describe()} forward, {self.stick[1].describe()} turn"
        elif self.value is not None:
            what = self.value.describe()
            if self.minus is not None:
                what += f" minus {self.minus.describe()}"
        else:
            assert self.press is not None
            what = f"press {BUTTON_NAMES[self.press]} (button {self.press})"
        params = f"=({','.join(self.params)})" if self.press is not None else ""
        return f"{what} -> {self.request}{params}"


@dataclass(frozen=True)
class Keyboard:
    """W/S forward and back, A/D turn, while held; Shift is turbo. Off when `request` is ""."""

    request: str = "base:base.drive"
    speed: float = 0.5
    turn: float = 0.5
    turbo_scale: float = 1.0


@dataclass(frozen=True)
class Profile:
    name: str
    source: str  # the file it came from
    description: str = ""
    deadman: int = 4
    turbo: int | None = 5
    bindings: tuple[Binding, ...] = ()
    keyboard: Keyboard = field(default_factory=Keyboard)

    @property
    def modules(self) -> tuple[str, ...]:
        """Modules this profile can move, in binding order: what a release stops."""
        seen: dict[str, None] = {}
        for b in self.bindings:
            seen.setdefault(b.module)
        if self.keyboard.request:
            seen.setdefault(self.keyboard.request.split(":", 1)[0])
        return tuple(seen)

    def summary(self) -> dict[str, Any]:
        """What the page shows in its mapping table."""
        rows = [{"input": f"hold {BUTTON_NAMES[self.deadman]} (button {self.deadman})",
                 "does": "dead-man enable: nothing moves unless held; release sends one stop"}]
        if self.turbo is not None:
            rows.append({"input": f"hold {BUTTON_NAMES[self.turbo]} (button {self.turbo})",
                         "does": "turbo: bindings use their turbo scale"})
        for b in self.bindings:
            what, _, target = b.describe().partition(" -> ")
            rows.append({"input": what, "does": target})
        if self.keyboard.request:
            rows.append({"input": "hold W/A/S/D (Shift: turbo)",
                         "does": f"{self.keyboard.request} from the keyboard"})
        return {"name": self.name, "source": self.source, "description": self.description,
                "rows": rows}


# --------------------------------------------------------------------------- YAML with lines


class _Node:
    """A YAML value and the line it starts on, for errors that point at the file."""

    def __init__(self, node: yaml.Node, file: str, path: str) -> None:
        self.node, self.file, self.path = node, file, path
        self.line = node.start_mark.line + 1

    def error(self, message: str, line: int | None = None) -> ProfileError:
        return ProfileError(message, file=self.file, line=line or self.line, key=self.path)

    def _child(self, node: yaml.Node, key: str) -> _Node:
        return _Node(node, self.file, f"{self.path}.{key}" if self.path else key)

    def mapping(self, allowed: tuple[str, ...]) -> dict[str, _Node]:
        if not isinstance(self.node, yaml.MappingNode):
            raise self.error("expected a mapping")
        out: dict[str, _Node] = {}
        for k, v in self.node.value:
            key = k.value if isinstance(k, yaml.ScalarNode) else None
            if not isinstance(key, str) or key not in allowed:
                raise ProfileError(f"unknown key {key!r}; expected one of {', '.join(allowed)}",
                                   file=self.file, line=k.start_mark.line + 1, key=self.path)
            if key in out:
                raise ProfileError(f"duplicate key {key!r}", file=self.file,
                                   line=k.start_mark.line + 1, key=self.path)
            out[key] = self._child(v, key)
        return out

    def sequence(self) -> list[_Node]:
        if not isinstance(self.node, yaml.SequenceNode):
            raise self.error("expected a list")
        return [self._child(v, str(i)) for i, v in enumerate(self.node.value)]

    def scalar(self) -> Any:
        if not isinstance(self.node, yaml.ScalarNode):
            raise self.error("expected a single value")
        try:
            return construct(self.node)
        except YamlError as exc:
            raise self.error(exc.problem, exc.line or None) from None

    def number(self, lo: float, hi: float, what: str = "a number") -> float:
        v = self.scalar()
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
                or not lo <= v <= hi:
            raise self.error(f"{v!r} is not {what} in {lo:g}..{hi:g}")
        return float(v)

    def index(self, count: int, what: str) -> int:
        v = self.scalar()
        if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < count:
            raise self.error(f"{v!r} is not {what} (0-{count - 1} in the standard mapping)")
        return v

    def text(self) -> str:
        v = self.scalar()
        if v is None:
            return ""
        if isinstance(v, bool) or not isinstance(v, str | int | float):
            raise self.error(f"{v!r} is not text")
        return str(v)

    def boolean(self) -> bool:
        v = self.scalar()
        if not isinstance(v, bool):
            raise self.error(f"{v!r} is not true or false")
        return v

    def target(self) -> str:
        v = self.text()
        if not _TARGET.match(v):
            raise self.error(f"{v!r} is not a request target (module:device.function)")
        return v


def _input(node: _Node) -> Input:
    keys = node.mapping(("axis", "button", "invert"))
    if ("axis" in keys) == ("button" in keys):
        raise node.error("expected exactly one of axis, button")
    invert = keys["invert"].boolean() if "invert" in keys else False
    if "axis" in keys:
        return Input("axis", keys["axis"].index(AXIS_COUNT, "an axis"), invert)
    return Input("button", keys["button"].index(BUTTON_COUNT, "a button"), invert)


_BINDING_KEYS = ("request", "name", "stick", "value", "minus", "press", "params", "deadzone",
                 "expo", "scale", "turbo_scale")


def _binding(node: _Node) -> Binding:
    keys = node.mapping(_BINDING_KEYS)
    if "request" not in keys:
        raise node.error("missing key 'request' (module:device.function)")
    request = keys["request"].target()
    kinds = [k for k in ("stick", "value", "press") if k in keys]
    if len(kinds) != 1:
        raise node.error("expected exactly one of stick, value, press")
    kind = kinds[0]
    stick = value = minus = None
    press = None
    params: tuple[str, ...] = ()
    if kind == "stick":
        sk = keys["stick"].mapping(("forward", "turn"))
        if set(sk) != {"forward", "turn"}:
            raise keys["stick"].error("expected both forward and turn")
        stick = (_input(sk["forward"]), _input(sk["turn"]))
    elif kind == "value":
        value = _input(keys["value"])
    else:
        press = keys["press"].index(BUTTON_COUNT, "a button")
    if "minus" in keys:
        if kind != "value":
            raise keys["minus"].error("minus goes with value")
        minus = _input(keys["minus"])
    if "params" in keys:
        if kind != "press":
            raise keys["params"].error("params go with press (stick and value compute theirs)")
        items = []
        for item in keys["params"].sequence():
            text = item.text()
            if not _PARAM.match(text):
                raise item.error(f"{text!r} is not an MCP parameter")
            items.append(text)
        params = tuple(items)
    scale = keys["scale"].number(0.0, 1.0, "a scale") if "scale" in keys else 1.0
    if scale == 0.0:
        raise keys["scale"].error("0 is not a scale in 0..1 (it would never move)")
    return Binding(
        request=request,
        name=keys["name"].text() if "name" in keys else request,
        stick=stick, value=value, minus=minus, press=press, params=params,
        deadzone=keys["deadzone"].number(0.0, 0.9, "a dead zone") if "deadzone" in keys
        else 0.1,
        expo=keys["expo"].number(0.0, 1.0, "an expo") if "expo" in keys else 0.0,
        scale=scale,
        turbo_scale=keys["turbo_scale"].number(0.0, 1.0, "a scale") if "turbo_scale" in keys
        else scale,
    )


def _keyboard(node: _Node) -> Keyboard:
    keys = node.mapping(("request", "speed", "turn", "turbo_scale"))
    request = keys["request"].target() if "request" in keys else Keyboard.request
    return Keyboard(
        request=request,
        speed=keys["speed"].number(0.0, 1.0, "a scale") if "speed" in keys else 0.5,
        turn=keys["turn"].number(0.0, 1.0, "a scale") if "turn" in keys else 0.5,
        turbo_scale=keys["turbo_scale"].number(0.0, 1.0, "a scale") if "turbo_scale" in keys
        else 1.0,
    )


def parse_profile(text: str, file: str, name: str) -> Profile:
    """A profile from YAML text; ProfileError naming file:line and the key otherwise."""
    try:
        root = compose(text)
    except YamlError as exc:
        raise ProfileError(exc.problem, file=file, line=exc.line) from None
    if root is None:
        raise ProfileError("the file is empty; expected a mapping with bindings", file=file,
                           line=1)
    top = _Node(root, file, "")
    keys = top.mapping(("description", "deadman", "turbo", "bindings", "keyboard"))
    if "bindings" not in keys:
        raise top.error("missing key 'bindings' (a list)")
    deadman = keys["deadman"].index(BUTTON_COUNT, "a button") if "deadman" in keys else 4
    turbo: int | None = 5
    if "turbo" in keys:
        turbo = None if keys["turbo"].scalar() is None else keys["turbo"].index(
            BUTTON_COUNT, "a button")
    if turbo == deadman:  # every motion would be at turbo_scale: holding the dead-man is turbo
        where = keys["turbo"] if "turbo" in keys else keys["deadman"]
        raise where.error(f"button {deadman} is both the dead-man and the turbo button; give "
                          "turbo another button (or turbo: null)")
    bindings = tuple(_binding(n) for n in keys["bindings"].sequence())
    reserved = {deadman: "dead-man"} | ({} if turbo is None else {turbo: "turbo"})
    for b, n in zip(bindings, keys["bindings"].sequence(), strict=True):
        if b.press in reserved:
            raise n.error(f"button {b.press} is already the dead-man or turbo button")
        # an input on the dead-man moved whenever motion was enabled, one on turbo whenever
        # turbo was held
        bk = n.mapping(_BINDING_KEYS)
        inputs = [(bk[k], i) for k, i in (("value", b.value), ("minus", b.minus)) if i]
        if b.stick is not None:
            sk = bk["stick"].mapping(("forward", "turn"))
            inputs += [(sk["forward"], b.stick[0]), (sk["turn"], b.stick[1])]
        for where, inp in inputs:
            if inp.kind == "button" and inp.index in reserved:
                raise where.error(
                    f"button {inp.index} is already the {reserved[inp.index]} button")
    keyboard = Keyboard()
    if "keyboard" in keys:
        kn = keys["keyboard"]
        if isinstance(kn.node, yaml.ScalarNode) and kn.scalar() in (None, False):
            keyboard = Keyboard(request="")
        else:
            keyboard = _keyboard(kn)
    return Profile(
        name=name, source=file,
        description=keys["description"].text() if "description" in keys else "",
        deadman=deadman, turbo=turbo, bindings=bindings, keyboard=keyboard,
    )


# --------------------------------------------------------------------------- where they live


def user_profile_dir(env: Mapping[str, str] | None = None) -> Path:
    """`$XDG_CONFIG_HOME/ramp/profiles`, or `~/.config/ramp/profiles`."""
    env = os.environ if env is None else env
    base = env.get("XDG_CONFIG_HOME") or ""
    root = Path(base) if base else Path(env.get("HOME") or Path.home()) / ".config"
    return root / "ramp" / "profiles"


def builtin_profile_dir() -> Path:
    return Path(str(resources.files("ramp.teleop").joinpath("profiles")))


class ProfileLibrary:
    """Every profile file an operator can pick, read fresh from disk on each load.

    Reading on each load means an operator edits a file and picks it again on the page;
    nothing needs a restart.
    """

    def __init__(self, dirs: list[Path] | None = None) -> None:
        self.dirs = dirs if dirs is not None else [builtin_profile_dir(), user_profile_dir()]

    def files(self) -> dict[str, Path]:
        """Profile name -> file; later directories (the operator's) win."""
        out: dict[str, Path] = {}
        for d in self.dirs:
            if d.is_dir():
                for f in sorted(d.glob("*.yaml")):
                    if _NAME.match(f.stem):
                        out[f.stem] = f
        return out

    def names(self) -> list[str]:
        return sorted(self.files(), key=lambda n: (n != DEFAULT_PROFILE, n))

    def load(self, name: str) -> Profile:
        files = self.files()
        path = files.get(name)
        if path is None:
            known = ", ".join(self.names()) or "none"
            where = ", ".join(str(d) for d in self.dirs)
            raise ProfileError(f"no profile named {name!r} (known: {known}; looked in {where})")
        try:
            text = read_text(path, what="a profile")
        except YamlError as exc:
            raise ProfileError(exc.problem, file=str(path), line=exc.line) from None
        return parse_profile(text, str(path), name)
