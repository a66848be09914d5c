"""The one simulation entry point: wires firmware_like emulators and physics to real drivers.

`ramp run --sim` replaces every bus, except those marked `sim: false`, by its emulator:
Sabertooth buses by the Sabertooth firmware emulator behind a pty (the real driver writes
real packets), CAN buses by the ODrive emulator on python-can's virtual bus, and Phidget
boards by the HAL-level sim driver (USB cannot be emulated). All of them move one MARTE
physics model, stepped by a scheduler task on the supervisor's clock.
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from firmware_like.marte import MarteWorld
from ramp.config import BusConfig, Config
from ramp.hal.interfaces import Bus
from ramp.hal.simio import SimBus
from ramp.supervisor import default_bus_factory

if TYPE_CHECKING:
    from ramp.supervisor import Supervisor

log = logging.getLogger("ramp.sim")


class SimBackplane:
    """Builds the simulated world and the bus for each config entry."""

    def __init__(self, config: Config, world: MarteWorld | None = None,
                 wire_level: bool = True) -> None:
        self.config = config
        self.world = world if world is not None else MarteWorld()
        self.wire_level = wire_level
        self.devices: list[Any] = []  # emulated devices serviced every tick
        self._tmp = tempfile.TemporaryDirectory(prefix="ramp-sim-")
        self.dir = Path(self._tmp.name)
        self.services: list[Callable[[float], None]] = []

    def bus_factory(self, bc: BusConfig) -> Bus:
        if not bc.sim:
            log.info("bus %s keeps its real %s driver (sim: false)", bc.name, bc.driver)
            return default_bus_factory(bc)
        if self.wire_level:
            bus = self._wire_level(bc)
            if bus is not None:
                return bus
        return SimBus(bc.name, dict(bc.params), world=self.world)

    def _wire_level(self, bc: BusConfig) -> Bus | None:
        """A real driver talking to an emulator, where one exists for this driver."""
        return None

    def attach(self, sup: Supervisor) -> None:
        """Step the world (and service emulators) first in every tick."""
        sup.scheduler.add_task("sim.world", sup.scheduler.rate_hz, self.tick)

    def tick(self, now: float, dt: float) -> None:
        for service in self.services:
            service(now)
        self.world.step(dt)

    def close(self) -> None:
        for dev in self.devices:
            close = getattr(dev, "close", None)
            if close is not None:
                close()
        self._tmp.cleanup()
