"""The runtime: builds the layers from a configuration and runs them on one scheduler."""

from __future__ import annotations

from ramp.runtime.supervisor import Supervisor, default_bus_factory

__all__ = ["Supervisor", "default_bus_factory"]
