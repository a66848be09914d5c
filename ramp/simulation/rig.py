"""The simulation rig: the arena world, the autonomy's sensors and their real drivers, on one
virtual clock and one scheduler.

What runs, in tick order (every task at the scheduler's base rate, 100 Hz):

- **the world** (`MarteWorld.step`), unless a backend is attached, whose backplane steps it;
- **the simulator's sensors**: the Hokuyo emulator (`firmware_like.hokuyo`, SCIP 2.0 on a
  loopback TCP port) fed by the ray-caster (`firmware_like.lidar_view`) from the LIDAR's true
  pose: the chassis' pose and attitude, the LIDAR mount and gimbal pivot of the autonomy's
  config, and the gimbal's *true* angles (the servo emulator's horns, which lag the
  controller); the IMU emulator (`firmware_like.imu`) bound to the world's truth, with the
  chosen fault (`none`, `gyro-drift`, `imu-shift`; seeded, the shift's moment drawn inside the
  run); the gimbal emulator (`firmware_like.servo`);
- **the autonomy's side** (`ramp.autonomy.perception.stack.Perception`): the real
  `HokuyoLidar` driver over real TCP to the emulator, `SimImu` and `SimPanTilt` (the `sim`
  drivers of the registry: USB cannot be emulated), odometry, the AHRS, the scan collector
  and the gimbal leveller.

**Geometry.** The world's LIDAR is placed from the same numbers the autonomy believes: the
config's `lidar.mount` and `gimbal.pivot` (`ramp.autonomy.mount.lidar_pose`), so the two can
never disagree; `autonomy.yaml` carries the simulator's mount (0.40, 0, 0.70) m
(`firmware_like/arena_params.py`), and a test checks both ways.

The simulator's side is `SimSensors`, on its own: `ramp sim mission --realtime` runs it in
the simulator's process and serves it to the autonomy's process over the sensor link
(`ramp.simulation.arena_process`).

**A backend** (`ramp.simulation.backend.SimBackend`) can be attached: the supervisor with its
sim backplane moving the same world on the same clock and scheduler, serving MCP on a loopback
port. The mission adds its MCP link (`ramp.autonomy.mcp_link.McpLink`) to `rig.scheduler`
and drives the world through the backend's real protocol stack.

Deterministic by seed: the layout's ground, the range noise, the IMU's noise, bias and
fault all come from `seed`, and nothing reads the wall clock.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import numpy.typing as npt

from firmware_like.arena_params import LidarParams
from firmware_like.hokuyo import HokuyoEmulator
from firmware_like.imu import FAULTS, ImuEmulator
from firmware_like.lidar_view import LidarPose, LidarView, rotation_zyx
from firmware_like.marte import MarteWorld
from firmware_like.randomize import Randomization
from firmware_like.servo import PanTiltEmulator, gimbal_emulator
from ramp.autonomy.config import AutonomyConfig, load_config
from ramp.autonomy.hal import driver_class
from ramp.autonomy.hal.hokuyo import HokuyoLidar
from ramp.autonomy.hal.interfaces import Imu, PanTilt
from ramp.autonomy.mount import lidar_pose
from ramp.autonomy.odometry import Odometry
from ramp.autonomy.perception.ahrs import Ahrs
from ramp.autonomy.perception.gimbal import GimbalLeveller
from ramp.autonomy.perception.scans import ScanCollector
from ramp.autonomy.perception.stack import Perception
from ramp.clock import Clock, VirtualClock
from ramp.scheduler import ScheduledTask, Scheduler
from ramp.simulation.backend import SimBackend

#: From the start of a UTM-30LX-EW scan to its beam straight ahead: step 540 of 1440 per turn
#: at 25 ms per turn (SPEC 6.2).
FRONT_STEP_DELAY_S = 540 / 1440 * 0.025
GIMBAL_HISTORY = 16  # ticks of true gimbal angles kept for the scans being cast

#: The repository's MARTE autonomy config: the default for every `ramp sim` command.
DEFAULT_AUTONOMY_YAML = Path(__file__).resolve().parents[2] / "autonomy.yaml"


def load_autonomy_config(path: str | Path | None = None) -> AutonomyConfig:
    """`autonomy.yaml` (the repository's MARTE one by default); ConfigErrors if it is bad."""
    return load_config(DEFAULT_AUTONOMY_YAML if path is None else path)


def shift_window(run_length_s: float) -> tuple[float, float]:
    """Where an `imu-shift` may fall in a run: anywhere from 10 % to 90 % of it, so it is
    neither hidden in the start-up nor after the end."""
    if not (math.isfinite(run_length_s) and run_length_s > 0.0):
        raise ValueError(f"run length {run_length_s!r} s must be > 0")
    return (0.1 * run_length_s, 0.9 * run_length_s)


class SimSensors:
    """The simulator's side of a rig: the Hokuyo emulator with its ray-caster, the IMU and
    gimbal emulators (and the world's step, unless a backend steps it), as tasks on
    `scheduler`. `Rig` puts the autonomy's drivers on them in the same process; in
    `ramp sim mission --realtime` the simulator's process serves them to the autonomy's
    process over the sensor link (`ramp.simulation.arena_process`)."""

    def __init__(self, world: MarteWorld, config: AutonomyConfig, scheduler: Scheduler, *,
                 seed: int = 0, fault: str = "none", run_length_s: float = 600.0,
                 shift_window_s: tuple[float, float] | None = None,
                 backend: SimBackend | None = None,
                 randomization: Randomization | None = None) -> None:
        if fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r} (expected one of: {', '.join(FAULTS)})")
        self.world = world
        self.config = config
        self.scheduler = scheduler
        self.clock: Clock = scheduler.clock
        self._tasks: list[ScheduledTask] = []
        rate = scheduler.rate_hz
        cfg = config
        if backend is None or not backend.steps_world:
            self._tasks.append(scheduler.add_task("sim.world", rate, self._step_world))
        self.gimbal_emulator: PanTiltEmulator = gimbal_emulator(self.clock, cfg.gimbal)
        m = cfg.lidar.mount
        true_mount = replace(LidarParams(), mount_x=m.x, mount_y=m.y, mount_z=m.z)
        imu_model = None
        if randomization is not None:  # the true mount and gyro; the autonomy keeps its own
            true_mount = randomization.lidar_params(true_mount)
            imu_model = randomization.imu_model()
        self.view = LidarView.of(world, true_mount, seed=seed)
        # The last GIMBAL_HISTORY ticks (a full deque drops its oldest as a tick is added).
        self._gimbal_times: deque[float] = deque(maxlen=GIMBAL_HISTORY)
        self._gimbal_angles: deque[tuple[float, float]] = deque(maxlen=GIMBAL_HISTORY)
        self.lidar_emulator = HokuyoEmulator(self.clock, self.range_source, port=0)
        self.lidar_emulator.attach(scheduler)
        self._tasks.append(scheduler.add_task("sim.lidar", rate, self._service_lidar))
        window = shift_window_s if shift_window_s is not None else shift_window(run_length_s)
        self.imu_emulator = ImuEmulator(self.clock, world.imu_truth, seed=seed,
                                        fault=fault, data_interval_ms=cfg.imu.data_interval_ms,
                                        mount=cfg.imu.mount, shift_window_s=window,
                                        model=imu_model)
        #: `sim:lidar.blind=(1)`: every beam returns nothing.
        self.lidar_blind = False
        if backend is not None:
            backend.sim_module.add_sensor_faults(self._set_blind, self.imu_emulator.shift_now)
        self.closed = False

    # -- the truth ------------------------------------------------------------------------------
    def true_lidar_pose(self, at: float | None = None) -> LidarPose:
        """The scanner's real pose in the arena: the chassis as the world has it, the gimbal
        as the servo horns stood at clock time `at` (now when None), the mount and pivot of
        the config."""
        pan, tilt = self.gimbal_emulator.angles() if at is None else self._gimbal_at(at)
        position, rotation = lidar_pose(self.config.lidar.mount, self.config.gimbal.pivot,
                                        pan, tilt)
        c = self.world.chassis_pose()
        chassis = rotation_zyx(c.yaw, c.pitch, c.roll)
        origin = np.array([c.x, c.y, c.z]) + chassis @ np.asarray(position)
        return LidarPose(origin, chassis @ np.asarray(rotation), math.radians(pan),
                         math.radians(tilt))

    def range_source(self, t: float) -> npt.NDArray[np.int64]:
        """The Hokuyo emulator's feed for the scan that started at `t`: one scan in
        millimetres, cast with the gimbal where it stood when the beam ahead was measured (the
        emulator asks once the scan is complete, up to a tick later; a sweeping gimbal moves
        meanwhile) and the chassis as it is now (it moves millimetres in that time)."""
        if self.lidar_blind:
            return np.full(self.view.params.steps, self.view.params.no_return_mm,
                           dtype=np.int64)
        front = t + FRONT_STEP_DELAY_S
        return self.view.scan(self.true_lidar_pose(front), digging=self.world.digging).mm

    def _gimbal_at(self, t: float) -> tuple[float, float]:
        """The horns' angles at clock time `t`, from the history kept."""
        now = self.gimbal_emulator.angles()
        times, angles = self._gimbal_times, self._gimbal_angles
        if not times or t >= self.clock.now():
            return now
        i = bisect.bisect_right(times, t)
        if i == 0:
            return angles[0]
        t0, a = times[i - 1], angles[i - 1]
        t1, b = (times[i], angles[i]) if i < len(times) else (self.clock.now(), now)
        f = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))

    def _set_blind(self, on: bool) -> None:
        self.lidar_blind = on

    def stop_tasks(self) -> None:
        """Take the tasks off the scheduler (the emulators stay as they are)."""
        for task in self._tasks:
            self.scheduler.remove_task(task)
        self._tasks.clear()

    def close(self) -> None:
        """Remove the tasks and close the Hokuyo emulator's port; idempotent."""
        if self.closed:
            return
        self.closed = True
        self.stop_tasks()
        self.lidar_emulator.close()

    # -- tasks ----------------------------------------------------------------------------------
    def _step_world(self, now: float, dt: float) -> None:
        self.world.step(dt)

    def _service_lidar(self, now: float, dt: float) -> None:
        self._gimbal_times.append(now)
        self._gimbal_angles.append(self.gimbal_emulator.angles())
        self.lidar_emulator.service(now)


class Rig:
    """World + emulators + the autonomy's drivers and perception tasks, ready to run."""

    def __init__(self, world: MarteWorld, config: AutonomyConfig | None = None, *,
                 seed: int = 0, fault: str = "none", run_length_s: float = 600.0,
                 shift_window_s: tuple[float, float] | None = None,
                 backend: SimBackend | None = None, rate_hz: float = 100.0,
                 stream: bool = True, randomization: Randomization | None = None) -> None:
        if fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r} (expected one of: {', '.join(FAULTS)})")
        self.world = world
        self.config = config if config is not None else load_autonomy_config()
        self.seed = seed
        self.fault = fault
        self.run_length_s = run_length_s
        self.backend = backend
        if backend is not None:
            self.clock: Clock = backend.clock
            self.scheduler: Scheduler = backend.scheduler
        else:
            self.clock = VirtualClock()
            self.scheduler = Scheduler(self.clock, rate_hz)
        now = self.clock.now()
        self.started_at = now
        cfg = self.config
        # -- the simulator's side ---------------------------------------------------------
        self.sensors = SimSensors(world, cfg, self.scheduler, seed=seed, fault=fault,
                                  run_length_s=run_length_s, shift_window_s=shift_window_s,
                                  backend=backend, randomization=randomization)
        self.gimbal_emulator = self.sensors.gimbal_emulator
        self.lidar_emulator = self.sensors.lidar_emulator
        self.imu_emulator = self.sensors.imu_emulator
        self.view = self.sensors.view
        # -- the autonomy's side ------------------------------------------------------------
        imu = driver_class("imu", "sim")(replace(cfg.imu, driver="sim"),
                                         emulator=self.imu_emulator)
        pan_tilt = driver_class("gimbal", "sim")(replace(cfg.gimbal, driver="sim"),
                                                 emulator=self.gimbal_emulator)
        lidar = HokuyoLidar(self.lidar_emulator.url, clock=self.clock, loop=self.scheduler)
        self.perception = Perception(cfg, lidar, imu, pan_tilt, now=now)
        self.perception.add_tasks(self.scheduler)
        self.perception.start(now, stream=stream)
        self.closed = False

    # -- shortcuts ------------------------------------------------------------------------------
    @property
    def lidar(self) -> HokuyoLidar:
        lidar = self.perception.lidar
        assert isinstance(lidar, HokuyoLidar)
        return lidar

    @property
    def ahrs(self) -> Ahrs:
        return self.perception.ahrs

    @property
    def leveller(self) -> GimbalLeveller:
        return self.perception.leveller

    @property
    def scans(self) -> ScanCollector:
        return self.perception.scans

    @property
    def odometry(self) -> Odometry:
        return self.perception.odometry

    @property
    def imu(self) -> Imu:
        return self.perception.imu

    @property
    def pan_tilt(self) -> PanTilt:
        return self.perception.pan_tilt

    @property
    def time(self) -> float:
        """Seconds since the rig was built."""
        return self.clock.now() - self.started_at

    @property
    def lidar_blind(self) -> bool:
        """`sim:lidar.blind=(1)`: every beam returns nothing."""
        return self.sensors.lidar_blind

    @lidar_blind.setter
    def lidar_blind(self, on: bool) -> None:
        self.sensors.lidar_blind = on

    # -- the truth ------------------------------------------------------------------------------
    def true_lidar_pose(self, at: float | None = None) -> LidarPose:
        """The scanner's real pose in the arena (`SimSensors.true_lidar_pose`)."""
        return self.sensors.true_lidar_pose(at)

    def range_source(self, t: float) -> npt.NDArray[np.int64]:
        """The Hokuyo emulator's feed (`SimSensors.range_source`)."""
        return self.sensors.range_source(t)

    # -- running --------------------------------------------------------------------------------
    def run_for(self, seconds: float) -> None:
        self.scheduler.run_for(seconds)

    def run_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Run until `done()` or `timeout_s` simulated seconds pass; True if done."""
        end = self.clock.now() + timeout_s
        self.scheduler.run(lambda: done() or self.clock.now() >= end)
        return done()

    def close(self) -> None:
        """Stop everything this rig started (and the backend, if attached); idempotent."""
        if self.closed:
            return
        self.closed = True
        self.sensors.stop_tasks()
        self.perception.close()
        self.sensors.close()
        if self.backend is not None:
            self.backend.close()

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
