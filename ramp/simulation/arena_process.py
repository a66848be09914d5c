"""`ramp sim mission --realtime`: the robot's backend, the simulated hardware and the autonomy
in three processes, as on the robot.

On the robot the backend and the autonomy are separate processes on separate loops, and the
hardware is hardware; in one process on one loop, the autonomy's heavy work (a 3D scan's
detection, a localization, a plan: tens to hundreds of milliseconds) made the backend's
100 Hz tick late by as much (issue 23), and the world's physics, the LIDAR's ray casting and
the emulators on the backend's loop made its figures the simulator's, not the robot's
(issue 35). So on the wall clock:

- **the simulator's process** (this module's `Arena`, a child of the command's process, on
  its own scheduler and `MonotonicClock`): the world and its physics, the Sabertooth
  emulators behind their ptys (`SimBackplane`'s bus emulators, built here; the backplane is
  stepped here, never attached to a supervisor), the Hokuyo emulator on loopback TCP, the IMU
  and gimbal emulators (`ramp.simulation.rig.SimSensors`);
- **the backend's process** (`ramp.simulation.backend_process`, started by the simulator's):
  the supervisor run exactly as `ramp run` runs it (`ramp.runtime.service.serve`: the stall
  guard's thread, `gc.freeze()`, SCHED_FIFO where permitted), its Sabertooth drivers on the
  simulator's ptys, the Phidget boards (which cannot cross a process at the wire) on the
  HAL-level sim driver fed over the **hardware link**, and the `sim` module, whose
  injections go to the simulator over the same link;
- **the command's process** (`ramp.simulation.mission.MissionRun`): the autonomy exactly as
  `ramp-autonomy` runs it on the robot, with the trace, the summary and the observers. The
  virtual-time run stays one process on one scheduler, deterministic.

Between the autonomy and the others: MCP over TCP to the backend and SCIP over TCP to the
Hokuyo, as on the robot, and the **sensor link** (`ramp.autonomy.hal.simlink`), a
socketpair serviced as a reader on each side's loop, carrying

- the IMU emulator's samples and the gimbal emulator's positions and target-reached events
  to the autonomy's `SimLinkImu` / `SimLinkPanTilt` drivers, and their commands back
  (`SensorServer`);
- `ready` (the backend's MCP address and pid and how it runs, the Hokuyo's address, the
  child's pid) once the backend serves, `truth` at 10 Hz (the world's t, x, y, yaw, lift,
  bin, delivered, the referee's counts and logs) for the trace and the observers
  (`MirroredWorld`), and `end` (the same, the backend's tick lateness over the whole run as
  its process measured it, `TickLog`, and the simulator's own) when the parent says `stop`.

Lifetime: the child runs until the parent says `stop` or the link closes (the parent died:
its end of the socketpair closes with it), or the backend's process ends; then it tells the
backend to stop (every motor zeroed on the wires, read here as the bytes arrive), sends
`end`, and closes its ports. It starts in a session of its own (the backend in the same),
so a Ctrl-C in the terminal reaches only the parent, which stops the robot and ends the
child; a child that dies closes both links, so the backend stops too and the parent ends the
run as `error`, saying so. ODrive buses (python-can's `virtual` bus, one process's) are not
supported here yet: the child refuses a config with a simulated CAN bus.

    python -m ramp.simulation.arena_process --link-fd N --options JSON   (the parent runs it)
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import math
import os
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

from ramp.autonomy.hal.simlink import SERVO_OPS, Message, SensorLink, sample_row
from ramp.scheduler import Scheduler

if TYPE_CHECKING:
    from firmware_like.imu import ImuEmulator
    from firmware_like.marte import MarteWorld
    from firmware_like.servo import PanTiltEmulator
    from ramp.simulation.mission import MissionOptions

log = logging.getLogger("ramp.sim.arena")

TRUTH_HZ = 10.0  # the trace's rate (SPEC 6.3)
READY_TIMEOUT_S = 60.0  # the child imports numpy, builds the world, opens the buses
END_TIMEOUT_S = 10.0  # for the child's `end` once told to stop
EXIT_TIMEOUT_S = 10.0  # then for it to exit, before SIGTERM, then SIGKILL
HISTOGRAM_US = 10.0  # lateness is counted in bins this wide
#: After the backend's shutdown, how long its zeros may take to reach the emulated motors
#: (the Sabertooth wire is paced at its baud rate: 0.1 s was seen; ASSUMPTION: 2.5x margin).
STOP_SETTLE_S = 0.25


class ArenaError(RuntimeError):
    """The simulator's process could not start, or ended when it should not have."""


# -- the backend's tick, measured in its own process ---------------------------------------
class TickLog:
    """Every tick's lateness over the whole run, counted as the scheduler's `TickStats`
    counts it (a tick's start, and a deadline that passed while a task still ran), through
    the loop's own hooks, in a histogram of `HISTOGRAM_US` bins: `TickStats` keeps only
    the last minute, and a run's first minute holds its 3D scan."""

    def __init__(self, scheduler: Scheduler) -> None:
        self.scheduler = scheduler
        self.bins: Counter[int] = Counter()
        self.count = 0
        self.max_us = 0.0
        self._next = math.inf
        self._chain_tick = scheduler.on_tick
        self._chain_done = scheduler.on_tick_done
        scheduler.on_tick = self.tick
        scheduler.on_tick_done = self.tick_done

    def _add(self, us: float) -> None:
        self.bins[int(us // HISTOGRAM_US)] += 1
        self.count += 1
        self.max_us = max(self.max_us, us)

    def tick(self, now: float, late_s: float) -> None:
        self._add(late_s * 1e6)
        period = self.scheduler.period
        self._next = now - late_s + (1 + int(late_s // period)) * period
        if self._chain_tick is not None:
            self._chain_tick(now, late_s)

    def tick_done(self, now: float, busy_s: float) -> None:
        after = now + busy_s
        if after > self._next:
            self._add((after - self._next) * 1e6)
        if self._chain_done is not None:
            self._chain_done(now, busy_s)

    def percentile_us(self, q: float) -> float:
        """The nearest-rank percentile (the scheduler's rule), to the bin's upper edge."""
        if not self.count:
            return 0.0
        rank = min(self.count - 1, int(q * self.count))
        seen = 0
        for b in sorted(self.bins):
            seen += self.bins[b]
            if seen > rank:
                return min(self.max_us, (b + 1) * HISTOGRAM_US)
        return self.max_us

    def report(self) -> dict[str, Any]:
        """Figures for the summary: lateness in µs, stalls and overruns since the start."""
        s = self.scheduler
        return {"pid": os.getpid(), "samples": self.count,
                "late_us": {"p50": round(self.percentile_us(0.50)),
                            "p99": round(self.percentile_us(0.99)),
                            "max": round(self.max_us)},
                "stalls": s.stalls, "overruns": s.stats.overruns, "skipped": s.stats.skipped,
                "last_overrun": s.stats.last_overrun_task}


# -- the simulator's side ------------------------------------------------------------------
class SensorServer:
    """The IMU and gimbal emulators served over the sensor link: their samples, positions
    and target-reached events out every tick, the drivers' commands in."""

    def __init__(self, link: SensorLink, imu: ImuEmulator, gimbal: PanTiltEmulator) -> None:
        self.link = link
        self.imu = imu
        self.gimbal = gimbal
        self.imu_open = False
        #: Values taken from the emulators that were not finite, so not sent.
        self.not_finite = 0
        link.on("imu.open", self._imu_open)
        link.on("imu.close", self._imu_close)
        link.on("imu.interval", lambda m: imu.set_data_interval(int(m["ms"])))
        link.on("imu.zero", lambda m: imu.zero_gyro())
        link.on("servo", self._servo)

    def _imu_open(self, msg: Message) -> None:
        self.imu.poll()  # what was measured while nobody listened is gone
        self.imu_open = True

    def _imu_close(self, msg: Message) -> None:
        self.imu_open = False

    def _servo(self, msg: Message) -> None:
        """One servo command, checked whole before it reaches the emulator: `engaged` takes
        only true or false, the others only a number (never a string or a bool)."""
        if not self.gimbal.attached:
            return  # the board is unplugged: the command goes nowhere, as over USB
        axis, op, value = msg.get("axis"), msg.get("op"), msg.get("v")
        if axis not in ("pan", "tilt"):
            raise ValueError(f"servo axis {axis!r}: expected pan or tilt")
        if op not in SERVO_OPS:
            raise ValueError(f"servo op {op!r}: expected target, velocity, acceleration, "
                             "engaged")
        channel = self.gimbal.pan if axis == "pan" else self.gimbal.tilt
        if op == "engaged":
            if not isinstance(value, bool):
                raise ValueError(f"servo {axis} engaged: expected true or false, "
                                 f"got {value!r:.40}")
            channel.set_engaged(value)
            return
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"servo {axis} {op}: expected a number, got {value!r:.40}")
        if op == "target":
            channel.set_target(float(value))
        elif op == "velocity":
            channel.set_velocity_limit(float(value))
        else:
            channel.set_acceleration(float(value))

    def tick(self, now: float, dt: float) -> None:
        """Every sample and event taken from the emulators this tick goes out: a value that
        is not finite (the link sends none) loses only itself, logged and counted in
        `not_finite`, never the rest of what was taken."""
        imu, g = self.imu, self.gimbal
        if self.imu_open:
            rows = [sample_row(s) for s in imu.poll()] if imu.attached else []
            good = [row for row in rows if all(map(math.isfinite, row))]
            self._count_bad("IMU samples", len(rows) - len(good))
            self.link.send("imu", attached=imu.attached, s=good)
        if g.attached:
            pos: list[float | None] = []
            reached: list[list[float]] = []
            for channel in (g.pan, g.tilt):
                p = channel.position_deg
                ok = p is None or math.isfinite(p)
                self._count_bad("servo positions", 0 if ok else 1)
                pos.append(p if ok else None)
                events = channel.take_reached()
                reached.append([deg for deg in events if math.isfinite(deg)])
                self._count_bad("target-reached events", len(events) - len(reached[-1]))
        else:
            pos, reached = [None, None], [[], []]
        self.link.send("gimbal", attached=g.attached, pos=pos, reached=reached)

    def _count_bad(self, what: str, n: int) -> None:
        if n:
            self.not_finite += n
            log.warning("sensor server: %d %s not finite, not sent", n, what)


def truth_of(world: MarteWorld) -> dict[str, Any]:
    """What the parent's trace, observers and summary read of the world."""
    return {"t": world.time, "x": world.x, "y": world.y, "yaw": world.yaw,
            "lift": world.lift_pos, "bin_kg": world.bin_kg,
            "delivered_kg": world.delivered_kg, "spilled_kg": world.spilled_kg,
            "excavated_kg": world.excavated_kg, "collisions": world.collisions,
            "crater_entries": world.crater_entries}


class _SensorFaults:
    """`SimSensors`' view of the backend: the backplane here steps the world, and the `sim`
    module's sensor faults (served by the backend's process) arrive over the hardware link."""

    steps_world = True

    def __init__(self) -> None:
        self.sim_module = self
        self.blind: Callable[[bool], None] = lambda on: None
        self.shift: Callable[[float], None] = lambda deg: None

    def add_sensor_faults(self, blind: Callable[[bool], None],
                          shift: Callable[[float], None]) -> None:
        self.blind, self.shift = blind, shift


class Arena:
    """The simulator's whole run: the world, the emulated hardware, the sensors and the link
    servers on one scheduler and the wall clock, and the backend in a process of its own
    (`ramp.simulation.backend_process`) on the emulated wires, until `stop` or the link
    closes."""

    def __init__(self, options: MissionOptions, link: SensorLink) -> None:
        from firmware_like.randomize import Randomization
        from ramp.clock import MonotonicClock
        from ramp.simulation.backend import DEFAULT_RAMP_YAML, load_backend_config
        from ramp.simulation.backplane import SimBackplane
        from ramp.simulation.mission import make_world, mission_config
        from ramp.simulation.rig import SimSensors, load_autonomy_config

        o = options
        self.link = link
        self.stopping = ""
        self.backend_ready: Message | None = None
        self.backend_end: Message | None = None
        self.backend_failed = ""
        randomization = Randomization.draw(o.seed) if o.randomize else None
        self.world = make_world(o, randomization)
        config = mission_config(load_autonomy_config(o.config), o.duration)
        backend_config = load_backend_config(DEFAULT_RAMP_YAML)
        self.scheduler = scheduler = Scheduler(MonotonicClock(), backend_config.rate_hz)
        # What is built is closed again if a later step fails: the backend's process stops
        # its motors and ends, the emulators close their ptys and ports.
        with contextlib.ExitStack() as built:
            self.backplane = SimBackplane(backend_config, self.world, wire_level=True)
            built.callback(self.backplane.close)
            self.ticks = TickLog(scheduler)  # the simulator's own loop, for comparison
            wire, self.inputs = self._wire(backend_config)
            scheduler.add_task("sim.world", scheduler.rate_hz, self._hardware_tick)
            faults = _SensorFaults()
            self.sensors = SimSensors(self.world, config, scheduler, seed=o.seed,
                                      fault=o.fault, run_length_s=o.duration,
                                      backend=faults,  # type: ignore[arg-type]
                                      randomization=randomization)
            built.callback(self.sensors.close)
            self.faults = faults
            self.server = SensorServer(link, self.sensors.imu_emulator,
                                       self.sensors.gimbal_emulator)
            self._logged = (0, 0)
            link.on("stop", lambda m: self.stop("the autonomy's process asked"))
            link.on_close.append(lambda why: self.stop(f"the sensor link closed: {why}"))
            link.attach(scheduler)
            scheduler.add_task("sim.link", scheduler.rate_hz, self.server.tick)
            scheduler.add_task("sim.truth", TRUTH_HZ, self._truth)
            self._sent_inputs: dict[str, Any] = {}
            self._sent_present: dict[str, bool] = {}
            values, present = self._input_values()
            self._sent_inputs, self._sent_present = dict(values), dict(present)
            spec = {"config": str(DEFAULT_RAMP_YAML), "port": o.port, "wire": wire,
                    "values": values, "present": present,
                    "can_jam": hasattr(self.world, "jam_lift"),
                    "rt_priority": o.backend_rt_priority}
            self._start_backend(spec)
            built.callback(self._end_backend)
            self._wait_backend(READY_TIMEOUT_S)
            built.pop_all()

    # -- the hardware the backend drives --------------------------------------------------------
    def _wire(self, config: Any) -> tuple[dict[str, dict[str, Any]], dict[str, str]]:
        """Each bus's emulator, built here: the params of the buses whose real driver the
        backend opens on an emulated wire (a pty), and the inputs (label -> the `SimWorld`
        read) of the HAL-level ones, whose values go over the hardware link."""
        from ramp.registry import emulators
        from ramp.simulation.backend_process import INPUT_READS

        wire: dict[str, dict[str, Any]] = {}
        for bc in config.buses.values():
            key = f"bus.{bc.driver}"
            if not bc.sim:
                wire[bc.name] = {}  # the real device: the backend opens it as configured
            elif key in emulators():
                if bc.driver == "can":
                    # python-can's virtual bus does not cross processes.
                    raise ArenaError(f"bus {bc.name}: a CAN bus cannot be emulated in the "
                                     "simulator's process yet (python-can's virtual bus is "
                                     "one process's)")
                wire[bc.name] = dict(emulators().load(key)(self.backplane, bc))
        inputs = {}
        for mname, mc in config.modules.items():
            for dname, dc in mc.devices.items():
                if dc.bus not in wire and dc.kind in INPUT_READS:
                    inputs[f"{mname}.{dname}"] = INPUT_READS[dc.kind]
        self.hal_buses = [name for name in config.buses if name not in wire]
        return wire, inputs

    def _input_values(self) -> tuple[dict[str, Any], dict[str, bool]]:
        signals = self.backplane.signals
        values = {label: getattr(signals, read)(label) for label, read in self.inputs.items()}
        present = {bus: bool(signals.bus_present(bus)) for bus in self.hal_buses}
        return values, present

    def _hardware_tick(self, now: float, dt: float) -> None:
        """The emulators read their wires, the world steps, and the HAL-level inputs that
        changed go to the backend."""
        self.backplane.tick(now, dt)
        values, present = self._input_values()
        changed = {k: v for k, v in values.items() if self._sent_inputs.get(k) != v}
        gone = {k: v for k, v in present.items() if self._sent_present.get(k) != v}
        if changed or gone:
            self._sent_inputs.update(changed)
            self._sent_present.update(gone)
            self.hw.send("in", v=changed, present=gone)

    def _out(self, msg: Message) -> None:
        """An output or motor of a HAL-level bus, as the backend's sim driver set it."""
        op, label, args = msg.get("op"), msg.get("label"), msg.get("args")
        if op not in ("set_motor", "write_digital", "set_servo") or not isinstance(
                label, str) or not isinstance(args, list):
            raise ValueError(f"hardware link: a bad output {msg!r:.80}")
        getattr(self.backplane.signals, op)(label, *args)

    def _sim(self, msg: Message) -> None:
        """What the backend's `sim` module injects (it checked the arguments)."""
        op, args = msg.get("op"), msg.get("args")
        if not isinstance(args, list):
            raise ValueError(f"hardware link: a bad injection {msg!r:.80}")
        bp = self.backplane
        actions: dict[Any, Callable[..., None]] = {
            "bus.unplug": bp.unplug, "bus.plug": bp.plug,
            "input.set": bp.signals.set_input, "input.clear": bp.signals.clear_input,
            "lift.jam": lambda on: self.world.jam_lift(bool(on)),
            "lidar.blind": lambda on: self.faults.blind(bool(on)),
            "imu.shift": lambda deg: self.faults.shift(float(deg))}
        if op not in actions:
            raise ValueError(f"hardware link: no injection {op!r:.40}")
        actions[op](*args)

    # -- the backend's process ------------------------------------------------------------------
    def _start_backend(self, spec: dict[str, Any]) -> None:
        mine, theirs = socket.socketpair()
        argv = [sys.executable, "-m", "ramp.simulation.backend_process",
                "--link-fd", str(theirs.fileno()), "--spec", json.dumps(spec)]
        self.backend_proc = subprocess.Popen(argv, pass_fds=(theirs.fileno(),),
                                             stdin=subprocess.DEVNULL,
                                             stdout=subprocess.DEVNULL)
        theirs.close()  # the backend's end: its death must close the link
        self.hw = hw = SensorLink(mine, name="hardware link (simulator)")
        hw.on("ready", lambda m: setattr(self, "backend_ready", m))
        hw.on("failed", lambda m: setattr(self, "backend_failed", str(m.get("error", ""))))
        hw.on("end", lambda m: setattr(self, "backend_end", m))
        hw.on("out", self._out)
        hw.on("sim", self._sim)
        hw.on_close.append(self._backend_lost)
        hw.attach(self.scheduler)

    def _wait_backend(self, timeout_s: float) -> None:
        """Run the hardware (the backend's drivers open on it) until the backend serves."""
        deadline = time.monotonic() + timeout_s
        self.scheduler.run(lambda: self.backend_ready is not None or self.hw.closed
                           or bool(self.backend_failed) or time.monotonic() > deadline)
        if self.backend_ready is None:
            why = self.backend_failed or (f"its link closed: {self.hw.reason}" if
                                          self.hw.closed else f"not ready in {timeout_s:g} s")
            raise ArenaError(f"the backend's process (pid {self.backend_proc.pid}) could "
                             f"not start: {why}")
        host, port = self.backend_ready["mcp"]
        #: Where the backend serves MCP.
        self.mcp_address: tuple[str, int] = (str(host), int(port))

    def _backend_lost(self, why: str) -> None:
        if self.backend_end is None and not self.stopping:
            code = self.backend_proc.poll()
            self.stop(f"the backend's process (pid {self.backend_proc.pid}) ended"
                      + (f" ({_status(code)})" if code is not None else "") + f": {why}")

    def _end_backend(self) -> None:
        """Tell the backend to stop (it stops every motor, then sends `end`), keep the
        hardware running meanwhile so its zeros reach the emulators, and see it exit."""
        proc = self.backend_proc
        if self.hw.connected and self.backend_end is None:
            self.hw.send("stop")
            deadline = time.monotonic() + END_TIMEOUT_S
            self.scheduler.run(lambda: self.backend_end is not None or self.hw.closed
                               or time.monotonic() > deadline)
        self.hw.close()
        try:
            proc.wait(EXIT_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            log.warning("the backend's process (pid %d) did not exit: SIGTERM", proc.pid)
            proc.terminate()
            try:
                proc.wait(5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()

    # -- the run --------------------------------------------------------------------------------
    def stop(self, why: str) -> None:
        if not self.stopping:
            self.stopping = why

    def run(self) -> int:
        ready = self.backend_ready or {}
        self.link.send("ready", pid=os.getpid(), mcp=ready.get("mcp"),
                       lidar=self.sensors.lidar_emulator.url,
                       backend_pid=ready.get("pid"), service=ready.get("service"))
        try:
            self.scheduler.run(lambda: bool(self.stopping))
            # Every motor stops before anything else: `end` may wait for the parent.
            motors = self.stop_motors()
            if self.link.connected:
                end = self.backend_end or {}
                self.link.send("end", why=self.stopping, backend=end.get("backend"),
                               simulator=self.ticks.report(), motors=motors,
                               **self._truth_fields(full=True))
                self.link.drain(2.0)
        finally:
            self.close()
        return 0

    def stop_motors(self) -> dict[str, float]:
        """The backend's shutdown (zeros on every wire, read here as they arrive), then the
        emulators read the wire until every motor of the world reads zero or `STOP_SETTLE_S`
        has passed; the world's motor duties as the robot was left (the summary's
        `motors_at_end`)."""
        from firmware_like.marte import MOTORS

        self._end_backend()
        world = self.world
        deadline = time.monotonic() + STOP_SETTLE_S
        while True:
            self.backplane.service_wire(self.scheduler.clock.now())
            duty = {name: world.duty(name) for name in MOTORS}
            if not any(duty.values()) or time.monotonic() >= deadline:
                break
            # The loop has ended: nothing else runs in this process, and the emulators
            # read the zeros off their ptys only as the bytes arrive. A short wait here
            # is the whole of shutdown, bounded by STOP_SETTLE_S.
            time.sleep(0.01)
        return duty

    def close(self) -> None:
        """The backend stopped (every motor), then the ports and the links closed; each step
        runs even if one before it raises. Idempotent."""
        try:
            self._end_backend()
        finally:
            try:
                self.sensors.close()
            finally:
                try:
                    self.backplane.close()
                finally:
                    self.link.close()

    def _truth_fields(self, full: bool = False) -> dict[str, Any]:
        w = self.world
        doc = truth_of(w)
        logs = (len(w.collision_log), len(w.crater_log))
        if full or logs != self._logged:
            self._logged = logs
            doc["collision_log"] = [[t, what] for t, what in w.collision_log]
            doc["crater_log"] = [[t, what] for t, what in w.crater_log]
        return doc

    def _truth(self, now: float, dt: float) -> None:
        self.link.send("truth", now=now, **self._truth_fields())


def main(argv: Sequence[str] | None = None) -> int:
    """The child's entry point (the parent, `ArenaProcess`, runs it)."""
    from ramp.simulation.mission import MissionOptions

    parser = argparse.ArgumentParser(prog="python -m ramp.simulation.arena_process")
    parser.add_argument("--link-fd", type=int, required=True)
    parser.add_argument("--options", required=True, help="MissionOptions as JSON")
    args = parser.parse_args(argv)
    # The terminal's Ctrl-C is the parent's to handle (it stops the robot, then says stop);
    # a SIGTERM sent here ends the run as `stop` does.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")
    link = SensorLink(socket.socket(fileno=args.link_fd), name="sensor link (simulator)")
    try:
        arena = Arena(MissionOptions(**json.loads(args.options)), link)
    except Exception as exc:  # noqa: BLE001 - said to the parent, which reports it
        link.send("failed", error=str(exc) if isinstance(exc, ArenaError)
                  else f"{type(exc).__name__}: {exc}")
        link.drain(2.0)
        link.close()
        return 1
    signal.signal(signal.SIGTERM, lambda signum, frame: arena.stop("SIGTERM"))
    return arena.run()


# -- the autonomy's side (the parent) -------------------------------------------------------
class MirroredWorld:
    """What the parent knows of the child's world: the layout (`describe`, `layout`,
    `start`), built from the same options as the child's, so the same; and the truth the
    child sends at 10 Hz, under the world's own names."""

    def __init__(self, layout_world: MarteWorld) -> None:
        self.layout_world = layout_world
        self.layout = layout_world.layout
        self.start = layout_world.start
        self.start_pose = layout_world.start_pose
        self.time = 0.0
        self.x, self.y, self.yaw = layout_world.x, layout_world.y, layout_world.yaw
        self.lift_pos = layout_world.lift_pos
        self.bin_kg = self.delivered_kg = self.spilled_kg = self.excavated_kg = 0.0
        self.collisions = self.crater_entries = 0
        self.collision_log: list[tuple[float, str]] = []
        self.crater_log: list[tuple[float, str]] = []

    @property
    def heading_deg(self) -> float:
        return math.degrees(self.yaw)

    def describe(self) -> dict[str, object]:
        return self.layout_world.describe()

    def update(self, msg: Message) -> None:
        """Take a `truth` (or `end`) message, checked whole first: a bad one changes
        nothing and raises ValueError naming the field."""
        v = {name: _finite(msg, name) for name in _TRUTH_FLOATS}
        counts = {name: _count(msg, name) for name in _TRUTH_COUNTS}
        logs = None
        if "collision_log" in msg:
            logs = (_log(msg, "collision_log"), _log(msg, "crater_log"))
        self.time = v["t"]
        self.x, self.y, self.yaw = v["x"], v["y"], v["yaw"]
        self.lift_pos = v["lift"]
        self.bin_kg = v["bin_kg"]
        self.delivered_kg = v["delivered_kg"]
        self.spilled_kg = v["spilled_kg"]
        self.excavated_kg = v["excavated_kg"]
        self.collisions = counts["collisions"]
        self.crater_entries = counts["crater_entries"]
        if logs is not None:
            self.collision_log, self.crater_log = logs


_TRUTH_FLOATS = ("t", "x", "y", "yaw", "lift", "bin_kg", "delivered_kg", "spilled_kg",
                 "excavated_kg")
_TRUTH_COUNTS = ("collisions", "crater_entries")


def _finite(msg: Message, name: str) -> float:
    return _finite_value(msg.get(name), name)


def _finite_value(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) \
            or not math.isfinite(value):
        raise ValueError(f"truth: {name}: expected a finite number, got {value!r:.40}")
    return float(value)


def _count(msg: Message, name: str) -> int:
    value = msg.get(name)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"truth: {name}: expected a count, got {value!r:.40}")
    return value


def _log(msg: Message, name: str) -> list[tuple[float, str]]:
    entries = msg.get(name)
    if not isinstance(entries, list):
        raise ValueError(f"truth: {name}: expected a list, got {entries!r:.40}")
    out = []
    for entry in entries:
        if not (isinstance(entry, list) and len(entry) == 2 and isinstance(entry[1], str)):
            raise ValueError(f"truth: {name}: expected [t, what], got {entry!r:.60}")
        out.append((_finite_value(entry[0], f"{name}: t"), entry[1]))
    return out


class ArenaProcess:
    """The child, seen from the parent: started (and waited for) on construction, its link
    serviced on the parent's scheduler once `attach`ed, ended by `finish` (idempotent)."""

    def __init__(self, options: MissionOptions, *,
                 ready_timeout_s: float = READY_TIMEOUT_S) -> None:
        mine, theirs = socket.socketpair()
        argv = [sys.executable, "-m", "ramp.simulation.arena_process",
                "--link-fd", str(theirs.fileno()), "--options", json.dumps(asdict(options))]
        self.proc = subprocess.Popen(argv, pass_fds=(theirs.fileno(),),
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     start_new_session=True)
        theirs.close()  # the child's end: its death must close the link
        self.pid = self.proc.pid
        self.link = SensorLink(mine, name="sensor link (autonomy)")
        self.ready: Message | None = None
        self.ended: Message | None = None
        self.failed = ""
        #: Why the child was lost before `finish` (empty while it was not), with its exit
        #: status once `finish` knows it.
        self.lost = ""
        self._lost_why = ""
        self.finishing = False
        self.on_truth: Callable[[Message], None] | None = None
        self.on_lost: Callable[[str], None] | None = None
        self.link.on("ready", self._ready)
        self.link.on("failed", self._failed)
        self.link.on("truth", self._truth)
        self.link.on("end", self._end)
        self.link.on_close.append(self._closed)
        try:
            self._wait_ready(ready_timeout_s)
        except BaseException:
            self.finish()
            raise
        ready: Message = self.ready or {}
        mcp = ready.get("mcp") or ("", 0)
        self.mcp_address: tuple[str, int] = (str(mcp[0]), int(mcp[1]))
        self.lidar_url = str(ready.get("lidar", ""))
        #: The backend's own process (the child starts it), and how it runs (`serve`).
        self.backend_pid = int(ready.get("backend_pid") or self.pid)
        service = ready.get("service")
        self.service: dict[str, Any] = service if isinstance(service, dict) else {}

    def _wait_ready(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while self.ready is None:
            if self.failed or self.link.closed:
                raise ArenaError(f"the simulator's process (pid {self.pid}) could not start: "
                                 f"{self.failed or self._exit_status(wait_s=2.0)}")
            left = deadline - time.monotonic()
            if left <= 0:
                raise ArenaError(f"the simulator's process (pid {self.pid}) was not ready "
                                 f"within {timeout_s:g} s")
            self.link.pump(min(left, 0.5))

    def attach(self, loop: Scheduler) -> None:
        """Service the link on the parent's scheduler from now on."""
        self.link.attach(loop)

    # -- the child's messages ----------------------------------------------------------------
    def _ready(self, msg: Message) -> None:
        self.ready = msg

    def _failed(self, msg: Message) -> None:
        self.failed = str(msg.get("error", "no reason given"))

    def _truth(self, msg: Message) -> None:
        if self.on_truth is not None:
            self.on_truth(msg)

    def _end(self, msg: Message) -> None:
        self.ended = msg
        if not self.finishing and self.on_lost is not None:
            self.on_lost(f"the simulator's process (pid {self.pid}) ended the run: "
                         f"{msg.get('why', '')}")

    def _closed(self, why: str) -> None:
        """The link closed before `finish`. This runs inside the loop's I/O callback, so it
        never waits for the child: `poll` says whether it is gone yet; if not (the parent
        closed the link itself, or the child's exit is not reaped yet), `finish` adds its
        exit status to `lost`."""
        if self.finishing or self.ended is not None or self.ready is None:
            return
        self._lost_why = why
        self.lost = self._lost_message(self.proc.poll(), by_itself=True)
        if self.on_lost is not None:
            self.on_lost(self.lost)

    def _lost_message(self, code: int | None, by_itself: bool) -> str:
        who = f"the simulator's process (pid {self.pid})"
        if code is not None and by_itself and code != 0:
            return f"{who} is gone ({_status(code)}); the sensor link: {self._lost_why}"
        text = f"{who} lost the sensor link: {self._lost_why}"
        if code is not None:
            text += f"; then it ended ({_status(code)})"
        return text

    def _exit_status(self, wait_s: float = 0.0) -> str:
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(wait_s)
        code = self.proc.returncode
        return "still running" if code is None else _status(code)

    # -- the end -----------------------------------------------------------------------------
    def finish(self, end_timeout_s: float = END_TIMEOUT_S) -> Message | None:
        """Tell the child to stop, take its `end` (the world's last truth and the backend's
        figures), and see it exit: SIGTERM, then SIGKILL if it does not. Idempotent; the
        `end` message, or None when the child could not send one."""
        if not self.finishing:
            self.finishing = True
            if self.link.connected and self.ended is None:
                self.link.send("stop")
                deadline = time.monotonic() + end_timeout_s
                while self.ended is None and self.link.connected \
                        and time.monotonic() < deadline:
                    self.link.pump(min(0.2, max(0.0, deadline - time.monotonic())))
            self.link.close()
        by_itself = self._reap()
        if self._lost_why:
            self.lost = self._lost_message(self.proc.returncode, by_itself)
        return self.ended

    def _reap(self) -> bool:
        """See the child exit, signalling it if it does not; True when it exited by
        itself."""
        if self.proc.poll() is not None:
            return True
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(EXIT_TIMEOUT_S)
            return True
        log.warning("the simulator's process (pid %d) did not exit: SIGTERM", self.pid)
        self.proc.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(5.0)
            return False
        self.proc.kill()
        self.proc.wait()
        return False


def _status(code: int) -> str:
    """A child's exit, as `Popen.returncode` gives it, in words."""
    if code >= 0:
        return f"exit status {code}"
    try:
        return f"killed by {signal.Signals(-code).name}"
    except ValueError:
        return f"killed by signal {-code}"


if __name__ == "__main__":
    sys.exit(main())
