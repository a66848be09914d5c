"""The autonomy's sensing, assembled: drivers in, AHRS, gimbal levelling, odometry and scan
records out, each a task on the one scheduler.

Built the same way on the robot (Phidget22 drivers, the Hokuyo at its address) and in
simulation (the `sim` drivers bound to emulators, the Hokuyo emulator on loopback): the caller
makes the three devices, this wires what stands on them. Task order within a tick follows the
data: drivers collect, odometry integrates, the AHRS takes in the new samples, the collector
samples the servo angles, the gimbal levels on the newest attitude. State estimation (the IMU
driver, odometry, the AHRS) runs at `estimation_hz`, every other tick by default; the LIDAR,
the collector and the gimbal every tick.
"""

from __future__ import annotations

from ramp.autonomy.config import AutonomyConfig
from ramp.autonomy.hal.interfaces import Imu, PanTilt
from ramp.autonomy.hal.lidar import READY, STREAMING, Lidar
from ramp.autonomy.odometry import Odometry
from ramp.autonomy.perception.ahrs import Ahrs, AhrsConfig
from ramp.autonomy.perception.gimbal import GimbalLeveller
from ramp.autonomy.perception.scans import ScanCollector
from ramp.scheduler import ScheduledTask, Scheduler


class Perception:
    """Devices plus the tasks that turn their readings into attitude, level and records."""

    def __init__(self, config: AutonomyConfig, lidar: Lidar, imu: Imu, pan_tilt: PanTilt, *,
                 now: float = 0.0, ahrs_config: AhrsConfig | None = None) -> None:
        self.config = config
        self.lidar = lidar
        self.imu = imu
        self.pan_tilt = pan_tilt
        self.odometry = Odometry(now=now)
        self.ahrs = Ahrs(imu, config.imu.mount, ahrs_config, moving=self.odometry.is_moving)
        self.leveller = GimbalLeveller(pan_tilt, self.ahrs.roll_pitch, config.lidar.mount)
        self.scans = ScanCollector(lidar, pan_tilt, self.ahrs, config.lidar.mount,
                                   config.gimbal.pivot)
        self.tasks: list[ScheduledTask] = []
        self._scheduler: Scheduler | None = None

    def add_tasks(self, scheduler: Scheduler) -> None:
        """Register every task, in data order: state estimation (IMU, odometry, AHRS) at
        `estimation_hz`; the LIDAR, the scan collector and the gimbal, which a sweep waits on
        at every tilt, at the base rate."""
        # On a loop `estimation_hz` does not divide (a test's), the nearest slower rate.
        base, estimation = scheduler.rate_hz, scheduler.rate_at_most(self.config.estimation_hz)
        self._scheduler = scheduler
        for name, rate, fn in (
                ("lidar", base, self.lidar.tick), ("imu", estimation, self.imu.tick),
                ("gimbal.servos", base, self.pan_tilt.tick),
                ("odometry", estimation, self.odometry.tick),
                ("ahrs", estimation, self.ahrs.tick), ("scans", base, self.scans.tick),
                ("gimbal.level", base, self.leveller.tick)):
            self.tasks.append(scheduler.add_task(f"autonomy.{name}", rate, fn))

    def start(self, now: float, *, stream: bool = True) -> None:
        """Open the boards and start connecting to the LIDAR (nothing here waits)."""
        self.imu.open(now)
        self.pan_tilt.open(now)
        self.lidar.start()
        if stream:
            self.lidar.start_stream()

    @property
    def ready(self) -> bool:
        """Every device answers, the AHRS has settled and the gimbal sits where asked."""
        return (self.imu.ready() and self.pan_tilt.ready()
                and self.lidar.state in (READY, STREAMING)
                and self.ahrs.settled and self.leveller.settled)

    def close(self) -> None:
        """Stop the tasks and let go of the devices; safe to call twice."""
        if self._scheduler is not None:
            for task in self.tasks:
                self._scheduler.remove_task(task)
            self.tasks.clear()
        self.scans.close()
        self.lidar.stop()
        self.imu.close()
        self.pan_tilt.close()
