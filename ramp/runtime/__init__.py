"""The runtime: builds the layers from a configuration and runs them on one scheduler.

`build(config, clock, bus_factory)` is the one way a robot is assembled (`ramp run`,
`ramp sim`, the tests and the benchmarks use it); an `Observer` sees the request path and
the robot's life at fixed points, for the flight recorder and the benchmarks.
"""

from __future__ import annotations

from ramp.runtime.build import BusFactory, build, default_bus_factory
from ramp.runtime.observers import Observer
from ramp.runtime.supervisor import Supervisor

__all__ = ["BusFactory", "Observer", "Supervisor", "build", "default_bus_factory"]
