"""Module type lookup: YAML `modules:` names (or their `type:`) -> module classes, through the
`ramp.modules` entry points (RAMP's own base, ble, diff_base and demo are registered in its
`pyproject.toml` like any plugin's; see `ramp.registry`)."""

from __future__ import annotations

from typing import Any

from ramp.registry import modules


def module_class(type_name: str) -> Any:
    """The module class registered as `type_name` (a `Module` subclass with class attributes
    `devices` and `settings`); ValueError lists the valid names."""
    return modules().load(type_name)


def module_types() -> list[str]:
    return modules().names()
