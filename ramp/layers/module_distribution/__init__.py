"""Module Distribution layer: each module's table-driven router (functions, get rows), the
one place a request is validated and `describe` comes from."""

from __future__ import annotations

from ramp.layers.module_distribution.router import (
    KINDS,
    BoundDevice,
    DeviceSpec,
    Function,
    Kind,
    Module,
    Property,
    Task,
    Version,
    answer,
)

__all__ = ["KINDS", "BoundDevice", "DeviceSpec", "Function", "Kind", "Module", "Property",
           "Task", "Version", "answer"]
