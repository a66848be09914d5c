"""Module type lookup: YAML `modules:` names (or their `type:`) -> module classes, through the
`ramp.modules` entry points (RAMP's own base, ble, diff_base and demo are registered in its
`pyproject.toml` like any plugin's; see `ramp.registry`)."""

from __future__ import annotations

from typing import Any

from ramp.api import Module
from ramp.registry import RegistryError, modules


def module_class(type_name: str) -> Any:
    """The module class registered as `type_name` (a `Module` subclass with class attributes
    `devices` and `settings`); ValueError lists the valid names, or says why the entry cannot
    be used (it fails to import, or is not a `ramp.api.Module` subclass)."""
    cls = modules().load(type_name)
    if not (isinstance(cls, type) and issubclass(cls, Module)):
        raise RegistryError(f"{modules().describe(modules().entry(type_name))} is "
                            f"{cls!r}, not a ramp.api.Module subclass")
    return cls


def module_types() -> list[str]:
    return modules().names()
