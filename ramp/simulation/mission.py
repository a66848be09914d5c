"""`ramp sim mission`: a whole RMC run in the simulator (SPEC 6.3), and `run_mission` for
`ramp sim campaign`.

One scheduler and one clock carry everything: the arena world, the backend (a real
`Supervisor` whose sim backplane moves the world, its Sabertooth buses behind ptys), the
Hokuyo emulator on loopback TCP, the IMU and gimbal emulators, and on the other side the
autonomy exactly as `ramp-autonomy` runs it on the robot (`ramp.autonomy.executive.Autonomy`):
its real drivers, its MCP link to the backend over TCP, the executive and the mission machine.
On the virtual clock a 10-minute run takes seconds and the same arguments give the same run;
with `realtime` it runs on the wall clock and serves MCP on a port an operator can use.

With `realtime` the simulated hardware and the arena run in a process of their own, and the
backend in another, run exactly as `ramp run` runs it (the stall guard's thread,
`gc.freeze()`, SCHED_FIFO where permitted), on the emulated wires
(`ramp.simulation.arena_process`, `ramp.simulation.backend_process`), so neither the
autonomy's heavy work nor the simulator's makes the backend's tick late; this process keeps
the autonomy, exactly as `ramp-autonomy` runs it, with its sensors over
SCIP/TCP and the sensor link (`ramp.autonomy.hal.simlink`), the trace, the summary and the
observers, which read the world's truth as the child sends it (`MirroredWorld`). The hidden
`single_loop` option runs realtime the old way, everything on one loop (issue 23's
comparison).

What comes out:

- every state change, as it happens (`on_change`);
- the trace (SPEC 6.3 `--trace`): a header with the true world, then the ground truth every
  0.1 s of simulated time, for anyone to referee the run (`ramp.simulation.referee`);
- the summary: `outcome` (`completed`, `waiting_for_operator` or `error`), `delivered_kg`,
  `collisions`, `crater_entries` (the world's referee counts), `states_visited`,
  `localization_losses`, `sim_time_s`, `wall_time_s`, `seed`, `start_box`, `heading`,
  `fault`, and more (`MissionRun.summary`).

The run ends when the mission is done, when it waits for an operator (unless `realtime`,
where an operator can come), or `END_GRACE_S` after the run's time at the latest.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from firmware_like.marte import MarteWorld
from firmware_like.randomize import Randomization
from firmware_like.world_file import load_world
from ramp.autonomy.config import AutonomyConfig
from ramp.autonomy.executive.autonomy import Autonomy
from ramp.autonomy.executive.kit import Detect, Localize
from ramp.clock import Clock
from ramp.common import accel
from ramp.scheduler import Scheduler
from ramp.simulation.backend import SimBackend
from ramp.simulation.rig import Rig, load_autonomy_config
from ramp.statemachine import StateChange

if TYPE_CHECKING:
    from ramp.autonomy.perception.stack import Perception
    from ramp.simulation.arena_process import ArenaProcess, MirroredWorld, TickLog

log = logging.getLogger("ramp.sim.mission")

QUALIFY_KG = 10.0  # SPEC 6.3: exit 0 with at least this delivered, no collision, no crater
TRACE_HZ = 10.0
END_GRACE_S = 5.0  # past the run's time, for the last stop to land
START_BOXES = ("left", "right")
HEADINGS = (0, 90, 180, 270)
FAULTS = ("none", "gyro-drift", "imu-shift")


@dataclass
class MissionOptions:
    """Everything that makes a run; the same options give the same run on virtual time."""

    seed: int = 0
    start_box: str | None = None  # None: from the seed (or the world file)
    heading: int | None = None
    fault: str = "none"
    duration: float = 600.0
    world: str | None = None  # a world file (SPEC 6.1); else `MarteWorld.seeded(seed)`
    config: str | None = None  # autonomy.yaml; default the repository's
    realtime: bool = False
    port: int = 0  # with realtime: where the backend serves MCP
    randomize: bool = False  # the seed also draws the robot's physics and calibration
    #: With realtime: the backend and the simulator on the autonomy's loop, in this process
    #: (realtime before issue 23; kept to measure the difference, `bench realtime`).
    single_loop: bool = False
    #: With realtime: serve the autonomy's command endpoint (SPEC 14) on this loopback port
    #: (0 picks one); the mission then waits for a supervisor's rmcMission.
    command_port: int | None = None
    #: With realtime: the backend's process runs SCHED_FIFO at this priority where permitted,
    #: as the service does (`scripts/ramp.service`); None: the default priority.
    backend_rt_priority: int | None = 20


@dataclass
class Sample:
    """One trace line's truth (SPEC 6.3)."""

    t: float
    x: float
    y: float
    yaw: float  # degrees
    lift: float
    bin_kg: float
    delivered_kg: float
    state: str

    def as_dict(self) -> dict[str, Any]:
        return {"t": round(self.t, 3), "x": round(self.x, 4), "y": round(self.y, 4),
                "yaw": round(self.yaw, 3), "lift": round(self.lift, 4),
                "bin_kg": round(self.bin_kg, 3), "delivered_kg": round(self.delivered_kg, 3),
                "state": self.state}


@dataclass
class MissionRun:
    """One run: build it, `run()` it, read `summary()`."""

    options: MissionOptions
    localize: Localize | None = None
    detect: Detect | None = None
    on_change: Callable[[StateChange], None] | None = None
    trace_file: IO[str] | None = None
    samples: list[Sample] = field(default_factory=list)
    changes: list[StateChange] = field(default_factory=list)
    #: Watchers of the run (the `--record` recorder): each may have `started(run)`,
    #: `sampled(run, now)` (10 Hz), `changed(run, change)` and `finished(run)`.
    observers: list[Any] = field(default_factory=list)

    def __post_init__(self) -> None:
        o = self.options
        if o.fault not in FAULTS:
            raise ValueError(f"fault {o.fault!r} is not one of {', '.join(FAULTS)}")
        if not (math.isfinite(o.duration) and o.duration > 0):
            raise ValueError(f"duration {o.duration!r} must be a positive number of seconds")
        self.randomization = Randomization.draw(o.seed) if o.randomize else None
        #: The arena; with `realtime` (not `single_loop`), its mirror once built.
        self.world: MarteWorld | MirroredWorld = make_world(o, self.randomization)
        self.config = mission_config(load_autonomy_config(o.config), o.duration)
        self.error = ""
        self.stop_requested = False  # `request_stop()`: end the run at the next tick
        self.commands: Any = None  # with `command_port`: the autonomy's command endpoint
        self.wall_s = 0.0
        self.started_at = math.nan
        self.ended_at = math.nan
        self.backend: SimBackend | None = None
        self.rig: Rig | None = None
        self.autonomy: Autonomy | None = None
        #: The autonomy's clock and scheduler (the rig's, unless the arena has a process).
        self.clock: Clock | None = None
        self.scheduler: Scheduler | None = None
        #: Where the backend serves MCP, once built.
        self.mcp_address: tuple[str, int] = ("", 0)
        #: With `realtime`: the simulator's process, and the backend's tick figures.
        self.arena: ArenaProcess | None = None
        self.perception: Perception | None = None  # with the arena apart: the autonomy's
        self.backend_ticks: dict[str, Any] | None = None
        #: With realtime: the simulator's own loop (the world, the emulators), for comparison.
        self.simulator_ticks: dict[str, Any] | None = None
        self._tick_log: TickLog | None = None
        self._arena_lost_why = ""  # the error the lost child set, if it set it
        #: With the arena apart: each motor's duty in the world once the child's backend
        #: had shut down (from its `end`), None when no `end` came.
        self.motors_at_end: dict[str, float] | None = None

    # -- the run ---------------------------------------------------------------------------------
    def build(self) -> None:
        o = self.options
        if o.realtime and not o.single_loop:
            self._build_apart()
            return
        clock = None
        if o.realtime:
            from ramp.clock import MonotonicClock

            clock = MonotonicClock()
        assert isinstance(self.world, MarteWorld)
        self.backend = SimBackend(self.world, clock=clock, port=o.port)
        if o.realtime:
            from ramp.simulation.arena_process import TickLog

            self._tick_log = TickLog(self.backend.scheduler)
        self.rig = Rig(self.world, self.config, seed=o.seed, fault=o.fault,
                       run_length_s=o.duration, backend=self.backend, stream=False,
                       randomization=self.randomization)
        self.clock, self.scheduler = self.rig.clock, self.rig.scheduler
        self.mcp_address = self.backend.address
        self.autonomy = Autonomy(self.rig.scheduler, self.rig.perception, self.config,
                                 self.backend.address, localize=self.localize,
                                 detect=self.detect)
        self.autonomy.mission.add_listener(self._changed)
        self.rig.scheduler.add_task("sim.trace", TRACE_HZ, self._sample)

    def _build_apart(self) -> None:
        """The simulated hardware and the arena in their own process (which starts the
        backend's, `ramp.simulation.backend_process`); the autonomy here, on its own
        scheduler and the wall clock, as `ramp-autonomy` runs on the robot."""
        from dataclasses import replace

        from ramp.autonomy.hal.hokuyo import HokuyoLidar
        from ramp.autonomy.hal.simlink import SimLinkImu, SimLinkPanTilt
        from ramp.autonomy.perception.stack import Perception
        from ramp.clock import MonotonicClock
        from ramp.simulation.arena_process import ArenaProcess, MirroredWorld

        assert isinstance(self.world, MarteWorld)
        self.arena = arena = ArenaProcess(self.options)
        self.world = MirroredWorld(self.world)
        self.clock = clock = MonotonicClock()
        self.scheduler = scheduler = Scheduler(clock, 100.0)
        self.mcp_address = arena.mcp_address
        arena.on_truth = self._truth
        arena.on_lost = self._arena_lost
        arena.attach(scheduler)
        cfg = self.config
        now = clock.now()
        lidar = HokuyoLidar(arena.lidar_url, clock=clock, loop=scheduler)
        imu = SimLinkImu(replace(cfg.imu, driver="simlink"), link=arena.link)
        pan_tilt = SimLinkPanTilt(replace(cfg.gimbal, driver="simlink"), link=arena.link)
        self.perception = Perception(cfg, lidar, imu, pan_tilt, now=now)
        self.perception.add_tasks(scheduler)
        self.perception.start(now, stream=False)
        self.autonomy = Autonomy(scheduler, self.perception, cfg, arena.mcp_address,
                                 localize=self.localize, detect=self.detect)
        self.autonomy.mission.add_listener(self._changed)
        self._command_endpoint()

    def _command_endpoint(self) -> None:
        """`command_port`: the supervisor's way in (ramp/autonomy/command.py)."""
        if self.options.command_port is None or self.autonomy is None:
            return
        from ramp.autonomy.command import CommandEndpoint

        assert self.scheduler is not None and self.clock is not None
        tracker = self.autonomy.kit.tracker
        self.commands = CommandEndpoint(self.autonomy.mission, pose=tracker.estimate,
                                        confidence=lambda: tracker.confidence,
                                        now=self.clock.now, port=self.options.command_port,
                                        kit=self.autonomy.kit)
        self.scheduler.add_task("autonomy.commands", 20.0, self.commands.tick)

    def run(self) -> dict[str, Any]:
        """Run to the end; the summary. Exceptions end the run as `error`."""
        wall0 = time.perf_counter()
        try:
            if self.autonomy is None:
                self.build()
            assert self.clock is not None and self.scheduler is not None
            assert self.autonomy is not None
            if self.trace_file is not None:
                header = {**self.world.describe(), "seed": self.options.seed,
                          "fault": self.options.fault, "duration": self.options.duration}
                self.trace_file.write(json.dumps(header) + "\n")
            clock = self.clock
            self.started_at = clock.now()
            self._notify("started")
            self.autonomy.start(self.started_at)
            mission = self.autonomy.mission
            waiting_ends = not self.options.realtime

            def over() -> bool:  # the budget's end: a commanded mission starts it later
                end = mission.context.budget.end_s + END_GRACE_S
                return (mission.over or self.stop_requested or clock.now() >= end
                        or (waiting_ends and mission.state == "waiting_for_operator"))

            self.scheduler.run(over)
            self.ended_at = clock.now()
            if self.arena is None or not self.arena_lost:
                # The last stop reaches the wheels, the trace shows it.
                self.scheduler.run_for(0.5)
        except KeyboardInterrupt:  # Ctrl-C (or SIGTERM, see the CLI) ends a --realtime run
            self.error = "interrupted"
            if self.clock is not None:
                self.ended_at = self.clock.now()
            self._stop_robot()
        except Exception as exc:  # noqa: BLE001 - the run's outcome, reported as `error`
            log.exception("mission run failed")
            self.error = f"{type(exc).__name__}: {exc}"
            if math.isnan(self.ended_at) and self.clock is not None:
                self.ended_at = self.clock.now()
        finally:
            self.wall_s = time.perf_counter() - wall0
            self._notify("finished")
            self.close()
        return self.summary()

    def request_stop(self) -> None:
        """End the run at the next tick (an observer that has seen enough, Ctrl-C)."""
        self.stop_requested = True

    def close(self) -> None:
        """Close the autonomy, then the rig or the backend, then (with the arena apart) the
        perception and the simulator's process: every step runs even if one before it
        raises, so the child never outlives a failed close."""
        if self._tick_log is not None:
            self.backend_ticks = self._tick_log.report()
            self._tick_log = None
        with contextlib.ExitStack() as steps:  # the callbacks run last first
            if self.arena is not None:
                steps.callback(self._finish_arena)
                if self.perception is not None:
                    steps.callback(self.perception.close)
            if self.rig is not None:
                steps.callback(self.rig.close)
            elif self.backend is not None:
                steps.callback(self.backend.close)
            if self.autonomy is not None:
                steps.callback(self.autonomy.close)
            if self.commands is not None:
                steps.callback(self.commands.close)

    def _finish_arena(self) -> None:
        assert self.arena is not None
        end = self.arena.finish()  # the child stops every motor and ends
        lost = self.arena.lost
        if lost and self.error == self._arena_lost_why and lost != self.error:
            log.error("%s", lost)  # now with the child's exit status
            self.error = self._arena_lost_why = lost
        if end is not None:
            self._truth(end, sample=False)
            self.backend_ticks = end.get("backend")
            self.simulator_ticks = end.get("simulator")
            motors = end.get("motors")
            if isinstance(motors, dict):
                self.motors_at_end = {str(k): v for k, v in motors.items()}

    @property
    def arena_lost(self) -> bool:
        """The simulator's process ended before the run did (the run is an `error`)."""
        return self.arena is not None and bool(self.error) and self.error != "interrupted"

    def _arena_lost(self, why: str) -> None:
        log.error("%s", why)
        if not self.error:
            self.error = self._arena_lost_why = why
        self.request_stop()

    def _stop_robot(self) -> None:
        """Interrupted: stop the robot over MCP before the link goes (the backend stops
        every motor at its shutdown too; this says so first, as `ramp-autonomy` does)."""
        autonomy = self.autonomy
        if autonomy is None or self.scheduler is None or self.clock is None:
            return
        try:
            if autonomy.mission.has_control:
                autonomy.robot.stop_all()
            end = self.clock.now() + 0.3
            self.scheduler.run(lambda: self.clock is None or self.clock.now() >= end)
        except KeyboardInterrupt:
            pass  # a second Ctrl-C: close at once

    # -- what it says --------------------------------------------------------------------------
    @property
    def outcome(self) -> str:
        if self.error or self.autonomy is None:
            return "error"
        state = self.autonomy.mission.state
        if state == "done":
            return "completed"
        if state == "waiting_for_operator":
            return "waiting_for_operator"
        return "error"

    def summary(self) -> dict[str, Any]:
        o, w = self.options, self.world
        start = w.start
        sim_s = (self.ended_at - self.started_at) if math.isfinite(self.started_at) else 0.0
        ctx = self.autonomy.context if self.autonomy is not None else None
        visited: list[str] = []
        for c in self.changes:
            if c.dest not in visited:
                visited.append(c.dest)
        doc: dict[str, Any] = {
            "outcome": self.outcome,
            "delivered_kg": round(w.delivered_kg, 3),
            "sim_time_s": round(sim_s, 2),
            "wall_time_s": round(self.wall_s, 2),
            "collisions": w.collisions,
            "crater_entries": w.crater_entries,
            "states_visited": visited,
            "localization_losses": ctx.localization_losses if ctx is not None else 0,
            "seed": o.seed,
            "start_box": start.box if start is not None else o.start_box,
            "heading": int(round(start.heading_deg)) if start is not None else o.heading,
            "fault": o.fault,
            "duration_s": o.duration,
            "world": w.layout.source,
            "qualified": bool(w.delivered_kg >= QUALIFY_KG and w.collisions == 0
                              and w.crater_entries == 0),
            "deposits": ctx.deposits if ctx is not None else 0,
            "faults": ctx.faults if ctx is not None else 0,
            "spilled_kg": round(w.spilled_kg, 3),
            "excavated_kg": round(w.excavated_kg, 3),
            "collision_log": [[round(t, 2), what] for t, what in w.collision_log],
            "crater_log": [[round(t, 2), what] for t, what in w.crater_log],
            "final_state": self.autonomy.mission.state if self.autonomy else "",
            "last_problem": ctx.last_problem if ctx is not None else "",
            "rtf": round(sim_s / self.wall_s, 1) if self.wall_s > 0 else None,
            # Whether the compiled hot path ran (ramp.common.accel): the same results, the
            # real-time factor about twice as high.
            "compiled": accel.status().active,
        }
        if self.randomization is not None:
            doc["randomized"] = self.randomization.as_dict()
        if o.realtime:
            doc["processes"] = {"autonomy": os.getpid(),
                                "backend": self.arena.backend_pid if self.arena
                                else os.getpid()}
            if self.arena is not None:
                doc["processes"]["simulator"] = self.arena.pid
                # How the backend runs: as `ramp run` (the stall guard, gc.freeze, priority).
                doc["backend_service"] = self.arena.service
            if self.backend_ticks is not None:
                doc["backend_tick"] = self.backend_ticks
            if self.simulator_ticks is not None:
                doc["simulator_tick"] = self.simulator_ticks
            if self.arena is not None:
                doc["motors_at_end"] = self.motors_at_end
        if self.error:
            doc["error"] = self.error
        return doc

    # -- tasks and listeners -------------------------------------------------------------------
    def mission_time(self, t: float) -> float:
        """Seconds since the mission started (clock time `t`)."""
        return t - self.started_at if math.isfinite(self.started_at) else 0.0

    def _changed(self, change: StateChange) -> None:
        self.changes.append(change)
        if self.on_change is not None:
            self.on_change(change)
        self._notify("changed", change)

    def _notify(self, hook: str, *args: Any) -> None:
        for observer in self.observers:
            fn = getattr(observer, hook, None)
            if fn is not None:
                fn(self, *args)

    def _truth(self, msg: dict[str, Any], sample: bool = True) -> None:
        """The child's truth (10 Hz, and its last at the end): the mirror, a trace line."""
        from ramp.simulation.arena_process import MirroredWorld

        assert isinstance(self.world, MirroredWorld)
        self.world.update(msg)
        if sample and self.clock is not None and math.isfinite(self.started_at):
            self._sample(self.clock.now(), 0.0)

    def _sample(self, now: float, dt: float) -> None:
        w = self.world
        state = self.autonomy.mission.state if self.autonomy is not None else "idle"
        s = Sample(w.time, w.x, w.y, w.heading_deg, w.lift_pos, w.bin_kg, w.delivered_kg, state)
        self.samples.append(s)
        if self.trace_file is not None:
            self.trace_file.write(json.dumps(s.as_dict()) + "\n")
        self._notify("sampled", now)


def make_world(o: MissionOptions, randomization: Randomization | None = None) -> MarteWorld:
    """The arena: a world file (its start unless a box or heading is given), or the seed's;
    with `randomization`, a robot that departs from the model by its draws."""
    params = randomization.marte_params() if randomization is not None else None
    if o.start_box is not None and o.start_box not in START_BOXES:
        raise ValueError(f"start box {o.start_box!r} is not one of {', '.join(START_BOXES)}")
    if o.heading is not None and o.heading not in HEADINGS:
        raise ValueError(f"heading {o.heading!r} is not one of {HEADINGS}")
    if o.world is None:
        return MarteWorld.seeded(o.seed, o.start_box,
                                 None if o.heading is None else float(o.heading), params=params)
    layout = load_world(o.world)
    if o.start_box is not None or o.heading is not None:
        from dataclasses import replace

        from firmware_like.arena import StartSpec

        old = layout.start
        box = o.start_box or (old.box if old is not None else "left")
        heading = float(o.heading) if o.heading is not None else (
            old.heading_deg if old is not None else 0.0)
        layout = replace(layout, start=StartSpec(box, heading))
    world = MarteWorld(params, seed=o.seed, layout=layout)
    touching = world.contacts()
    if touching:  # a start in contact would be a collision the summary never counts
        s = world.start_pose
        raise ValueError(f"{o.world}: the start at x {s.x:.3f}, y {s.y:.3f}, yaw "
                         f"{s.yaw_deg:.1f} touches {', '.join(touching)}; expected a start "
                         "clear of the walls and obstacles")
    return world


def mission_config(config: AutonomyConfig, duration: float) -> AutonomyConfig:
    """The autonomy's config with the run's length (`--duration`) as the mission's."""
    from dataclasses import replace
    from types import MappingProxyType

    mission = dict(config.mission)
    mission["duration_s"] = float(duration)
    return replace(config, mission=MappingProxyType(mission))


def run_mission(seed: int, start_box: str, heading: int, fault: str = "none",
                duration: float = 600.0, randomize: bool = False) -> dict[str, Any]:
    """One simulated mission's SPEC 6.3 summary, for `ramp sim campaign`."""
    run = MissionRun(MissionOptions(seed=seed, start_box=start_box, heading=heading,
                                    fault=fault, duration=duration, randomize=randomize))
    return run.run()


def write_trace(path: str | Path) -> IO[str]:
    return open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed by the caller
