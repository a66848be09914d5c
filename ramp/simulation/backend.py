"""The backend in a simulation rig: a real `Supervisor` moving the rig's `MarteWorld`.

`ramp run --sim` in-process, on the rig's virtual clock: the backplane
(`ramp.simulation.backplane.SimBackplane`) puts every bus on its emulator (the Sabertooths
behind ptys, the Phidget boards at the HAL) and steps the world first in every tick, and
the supervisor serves MCP on a loopback port. An autonomy then talks to it over real TCP
(`ramp.autonomy.mcp_link.McpLink`) from tasks on the same scheduler, so a whole mission runs
in one thread on one clock, deterministically.

This is simulation glue (it imports the backend); the autonomy never imports it.
"""

from __future__ import annotations

from pathlib import Path

from firmware_like.marte import MarteWorld
from ramp.clock import Clock, VirtualClock
from ramp.config import Config, check_config
from ramp.errors import ConfigErrors
from ramp.runtime import build
from ramp.scheduler import Scheduler
from ramp.simulation.backplane import SimBackplane
from ramp.simulation.sim_module import SimModule

#: The repository's MARTE wiring, what `ramp run --sim` uses by default.
DEFAULT_RAMP_YAML = Path(__file__).resolve().parents[2] / "ramp.yaml"


def load_backend_config(path: str | Path = DEFAULT_RAMP_YAML) -> Config:
    config, errors = check_config(path)
    if errors or config is None:
        raise ConfigErrors(errors)
    return config


class SimBackend:
    """A started supervisor on `clock`, moving `world`; `address` is where it serves MCP."""

    #: The backplane steps the world in its first task: the rig must not step it again.
    steps_world = True

    def __init__(self, world: MarteWorld, clock: Clock | None = None,
                 config: Config | str | Path = DEFAULT_RAMP_YAML, *,
                 wire_level: bool = True, port: int = 0) -> None:
        self.world = world
        # A virtual clock by default; `ramp sim mission --realtime` gives the wall clock.
        self.clock: Clock = clock if clock is not None else VirtualClock()
        self.config = config if isinstance(config, Config) else load_backend_config(config)
        self.backplane = SimBackplane(self.config, world, wire_level=wire_level)
        self.supervisor = build(self.config, self.clock, self.backplane.bus_factory,
                                host="127.0.0.1", port=port)
        self.backplane.attach(self.supervisor)
        self.supervisor.start()
        self.supervisor.settle()
        self.closed = False

    @property
    def sim_module(self) -> SimModule:
        """The `sim` module (SPEC 12) its backplane added to the robot."""
        module = self.backplane.sim_module
        assert isinstance(module, SimModule)
        return module

    @property
    def scheduler(self) -> Scheduler:
        return self.supervisor.scheduler

    @property
    def address(self) -> tuple[str, int]:
        host, port = self.supervisor.server.address
        return str(host), int(port)

    def close(self) -> None:
        """Stop every motor, close the buses and the server; safe to call twice."""
        if self.closed:
            return
        self.closed = True
        self.supervisor.shutdown()
        self.backplane.close()
