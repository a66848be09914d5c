"""Module type registry: YAML `modules:` names (or their `type:`) -> module class, lazily."""

from __future__ import annotations

import importlib
from typing import Any

MODULE_TYPES: dict[str, tuple[str, str]] = {
    "base": ("ramp.modules.base", "BaseModule"),
    "ble": ("ramp.modules.ble", "BleModule"),
    "demo": ("ramp.modules.demo", "DemoModule"),
}


def module_class(type_name: str) -> Any:
    """The module class registered as `type_name` (a `ModuleFactory` with class attributes
    `devices` and `settings`); ValueError lists the valid names."""
    try:
        mod, cls = MODULE_TYPES[type_name]
    except KeyError:
        raise ValueError(
            f"unknown module type {type_name!r} (expected one of: "
            f"{', '.join(sorted(MODULE_TYPES))})") from None
    return getattr(importlib.import_module(mod), cls)
