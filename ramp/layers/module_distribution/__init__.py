"""Module Distribution layer: each module's table-driven router (functions, get rows)."""

from __future__ import annotations

from ramp.layers.module_distribution.router import (
    BoundDevice,
    DeviceSpec,
    Function,
    Kind,
    Module,
    Property,
    Task,
)

__all__ = ["BoundDevice", "DeviceSpec", "Function", "Kind", "Module", "Property", "Task"]
