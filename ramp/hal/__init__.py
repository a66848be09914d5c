"""Driver lookup: YAML `driver:` names -> Bus classes, through the `ramp.drivers` entry points.

RAMP's own drivers (sabertooth, phidget, can, sim) are registered in its `pyproject.toml`
exactly as a plugin's are (`ramp.registry`); each is imported only when a bus uses it, so a
missing vendor library breaks only the driver that needs it.
"""

from __future__ import annotations

from ramp.hal.interfaces import Bus
from ramp.registry import RegistryError, drivers


def driver_class(name: str) -> type[Bus]:
    """The Bus class registered as `name`; ValueError lists the valid names (or names the two
    packages that both registered it)."""
    cls = drivers().load(name)
    if not (isinstance(cls, type) and issubclass(cls, Bus)):
        raise RegistryError(f"{drivers().describe(drivers().entry(name))} is {cls!r}, not a "
                            "ramp.api.Bus subclass")
    return cls


def driver_names() -> list[str]:
    return drivers().names()
