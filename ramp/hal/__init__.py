"""Driver registry: YAML `driver:` names -> (module, class), imported lazily.

A missing vendor library (Phidget22, a CAN backend) breaks only the driver that needs it.
"""

from __future__ import annotations

import importlib

from ramp.hal.interfaces import Bus

DRIVERS: dict[str, tuple[str, str]] = {
    "sim": ("ramp.hal.simio", "SimBus"),
    "sabertooth": ("ramp.hal.sabertooth", "SabertoothBus"),
    "phidget": ("ramp.hal.phidget", "PhidgetBus"),
    "can": ("ramp.hal.odrive", "ODriveBus"),
}


def driver_class(name: str) -> type[Bus]:
    """The Bus class registered as `name`; ValueError lists the valid names."""
    try:
        module_name, class_name = DRIVERS[name]
    except KeyError:
        raise ValueError(
            f"unknown driver {name!r} (expected one of: {', '.join(sorted(DRIVERS))})"
        ) from None
    module = importlib.import_module(module_name)
    cls: type[Bus] = getattr(module, class_name)
    return cls
