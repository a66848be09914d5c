"""Plugin registries: module types, bus drivers and emulators, from Python entry points.

One route for everything (python-can's `can.interface` table is the anchor): RAMP's own
modules, drivers and emulators are declared in RAMP's `pyproject.toml` under the same entry
point groups a third-party package uses, so adding one is installing a package, and there is
no list in the code to edit. The table is read from `importlib.metadata` once per process and
an entry is imported only when it is used, so a missing vendor library (Phidget22, a CAN
backend) breaks only the one entry that needs it.

Groups:
- `ramp.modules`: YAML `modules: {NAME: {type: TYPE}}` -> a `ramp.api.Module` subclass;
- `ramp.drivers`: YAML `buses: {NAME: {driver: DRIVER}}` -> a `ramp.api.Bus` subclass;
- `ramp.emulators`: what `--sim` puts behind a driver (`bus.DRIVER`: a callable building the
  emulated bus) or a module (`module.TYPE`: a physics part of the simulated world).

A name registered by two distributions is an error naming both, raised when that name is
used (the other names keep working), so `ramp check` shows it at the YAML key that needs it.
So is an entry that cannot be loaded, whatever its code raised (a missing library, a syntax
error, an exception at import): a `PluginLoadError` naming the entry point, its distribution
and the plugin's file and line, never a traceback.
"""

from __future__ import annotations

import importlib
import importlib.metadata as md
import traceback
from dataclasses import dataclass
from typing import Any

GROUPS = ("ramp.modules", "ramp.drivers", "ramp.emulators")
_WHAT = {"ramp.modules": "module type", "ramp.drivers": "driver", "ramp.emulators": "emulator"}


class RegistryError(ValueError):
    """A name that is unknown, registered twice, or whose entry cannot be imported."""


class PluginLoadError(RegistryError, ImportError):
    """An entry whose code failed to import (an ImportError too: a missing vendor library)."""


@dataclass(frozen=True)
class Entry:
    """One registered name: where it points and which installed distribution declared it."""

    name: str
    value: str  # "package.module:attribute"
    distribution: str


class Registry:
    """One entry point group as a lazy name -> object table."""

    def __init__(self, group: str, entries: list[Entry] | None = None) -> None:
        self.group = group
        self._given = entries
        self._table: dict[str, list[Entry]] | None = None
        self._loaded: dict[str, Any] = {}

    def _entries(self) -> dict[str, list[Entry]]:
        if self._table is None:
            found = self._given if self._given is not None else _installed(self.group)
            table: dict[str, list[Entry]] = {}
            for e in found:
                same = table.setdefault(e.name, [])
                # One distribution seen twice on sys.path (an editable install beside a build
                # directory) is one registration, not a conflict.
                if not any(o.distribution == e.distribution and o.value == e.value for o in same):
                    same.append(e)
            self._table = table
        return self._table

    def names(self) -> list[str]:
        """Every registered name, sorted."""
        return sorted(self._entries())

    def __contains__(self, name: object) -> bool:
        return name in self._entries()

    def entry(self, name: str) -> Entry:
        """The one entry for `name`; RegistryError when unknown or registered twice."""
        found = self._entries().get(name)
        if not found:
            kind = _WHAT.get(self.group, self.group)
            raise RegistryError(f"unknown {kind} {name!r} (expected one of: "
                                f"{', '.join(self.names()) or 'none installed'})")
        if len(found) > 1:
            who = " and ".join(f"{e.distribution} ({e.value})" for e in found)
            raise RegistryError(f"{name!r} is registered twice in {self.group}, by {who}; "
                                "uninstall one of them")
        return found[0]

    def load(self, name: str) -> Any:
        """The object registered as `name`, imported on first use."""
        if name in self._loaded:
            return self._loaded[name]
        e = self.entry(name)
        module_name, _, attr = e.value.partition(":")
        try:
            obj: Any = importlib.import_module(module_name)
        except Exception as exc:  # a plugin's code: anything it raises is its load error
            raise PluginLoadError(f"{self.describe(e)} cannot be loaded: {where(exc)}"
                                  f"{type(exc).__name__}: {exc}") from exc
        try:
            for part in attr.split(".") if attr else ():
                obj = getattr(obj, part)
        except AttributeError as exc:
            raise RegistryError(f"{self.group} entry {name!r} of {e.distribution} points at "
                                f"{e.value}, which does not exist: {exc}") from exc
        self._loaded[name] = obj
        return obj

    def describe(self, e: Entry) -> str:
        """`module type 'arm' (entry point arm = ramp_arm.module:ArmModule of ramp-arm)`."""
        return (f"{_WHAT.get(self.group, self.group)} {e.name!r} (entry point {e.name} = "
                f"{e.value} in {self.group} of {e.distribution})")


def origin(group: str, name: str) -> str:
    """Who provides `name` in `group`, for a log line or a fault reason (never raises):
    `acme-crane's entry point crane = acme_crane.module:Crane`."""
    try:
        e = registry(group).entry(name)
    except (RegistryError, ValueError):
        return f"{_WHAT.get(group, group)} {name} (not registered)"
    return f"{e.distribution}'s entry point {e.name} = {e.value}"


def where(exc: BaseException) -> str:
    """`FILE:LINE: ` of the plugin's code that raised (its innermost frame outside the import
    machinery; a syntax error's own place), or '' when the import found no file at all."""
    if isinstance(exc, SyntaxError) and exc.filename:
        return f"{exc.filename}:{exc.lineno}: "
    frames = [f for f in traceback.extract_tb(exc.__traceback__)
              if not f.filename.startswith("<") and "importlib" not in f.filename]
    frames = [f for f in frames if f.filename != __file__]
    return f"{frames[-1].filename}:{frames[-1].lineno}: " if frames else ""


def _installed(group: str) -> list[Entry]:
    out = []
    for ep in md.entry_points(group=group):
        dist = ep.dist.name if ep.dist is not None else "?"
        out.append(Entry(ep.name, ep.value, dist))
    return out


_REGISTRIES: dict[str, Registry] = {}


def registry(group: str) -> Registry:
    """The process's table for `group` (read once, on first use)."""
    if group not in GROUPS:
        raise ValueError(f"unknown entry point group {group!r} (expected one of: "
                         f"{', '.join(GROUPS)})")
    reg = _REGISTRIES.get(group)
    if reg is None:
        reg = _REGISTRIES[group] = Registry(group)
    return reg


def modules() -> Registry:
    return registry("ramp.modules")


def drivers() -> Registry:
    return registry("ramp.drivers")


def emulators() -> Registry:
    return registry("ramp.emulators")
