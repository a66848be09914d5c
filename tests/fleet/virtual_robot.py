"""A simulated MARTE with the autonomy on the virtual clock, in this process: the arena, the
backend (serving MCP on loopback), the autonomy and its command endpoint (on loopback too,
with node tasks), all on one scheduler. `run_until(pred)` runs simulated time as fast as the
machine goes until `pred()` holds; clients on the wall clock (a fleet agent in its own
process) are answered whenever the loop polls its sockets, so they see a robot that drives
many times faster than real, and waits for them at no cost."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from ramp.autonomy.command import CommandEndpoint
from ramp.simulation.mission import MissionOptions, MissionRun

ASK_EVERY_S = 0.05


class VirtualRobot:
    def __init__(self, seed: int = 1, duration: float = 3600.0) -> None:
        self.run = MissionRun(MissionOptions(seed=seed, duration=duration))
        self.run.build()
        autonomy = self.run.autonomy
        assert autonomy is not None and self.run.scheduler is not None
        assert self.run.clock is not None
        self.scheduler = self.run.scheduler
        self.clock = self.run.clock
        tracker = autonomy.kit.tracker
        self.endpoint = CommandEndpoint(autonomy.mission, pose=tracker.estimate,
                                        confidence=lambda: tracker.confidence,
                                        now=self.clock.now, kit=autonomy.kit)
        self.scheduler.add_task("autonomy.commands", 20.0, self.endpoint.tick)
        autonomy.start(self.clock.now())
        self.mcp = self.run.mcp_address
        self.commands = "{}:{}".format(*self.endpoint.address)

    @property
    def world(self) -> Any:
        return self.run.world

    def run_until(self, pred: Callable[[], bool], wall_s: float = 60.0,
                  sim_s: float = 1800.0, every_s: float = 0.0) -> None:
        """Run until `pred()`, asked at every tick, or at most every `every_s` of wall time
        (`ASK_EVERY_S` for a costly question, which would slow the simulation: the run may
        then go on for some simulated time after it holds); AssertionError past `wall_s` of
        wall time or `sim_s` of simulated time."""
        wall_end = time.monotonic() + wall_s
        sim_end = self.clock.now() + sim_s
        timed_out: list[str] = []
        asked = [-math.inf]

        def stop() -> bool:
            t = time.monotonic()
            if t - asked[0] >= every_s:
                asked[0] = t
                if pred():
                    return True
            if time.monotonic() > wall_end or self.clock.now() > sim_end:
                timed_out.append(f"{time.monotonic() - wall_end + wall_s:.0f} s wall, "
                                 f"{self.clock.now() - sim_end + sim_s:.0f} s simulated")
                return True
            return False

        self.scheduler.run(stop)
        if timed_out:
            raise AssertionError(f"not reached after {timed_out[0]}")

    def task(self) -> dict[str, Any]:
        return self.endpoint.tasks.status() or {} if self.endpoint.tasks else {}

    def close(self) -> None:
        self.endpoint.close()
        self.run.close()
