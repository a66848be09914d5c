"""`--randomize` (SPEC 6.3): the physics and calibration a real robot never matches exactly,
drawn from the seed, so the autonomy is tried on robots that are not its model.

Each draw is a parameter handed to the world, the LIDAR view and the IMU emulator when they
are built (never an edit of them afterwards), and the autonomy is not told any of it:

- skid-steer efficiency and traction, each x U(0.85, 1.15);
- each wheel's speed error, x U(0.95, 1.05);
- the LIDAR mount's yaw, U(-1, 1) deg, and its x and y, U(-1, 1) cm;
- a constant gyro bias on each axis, U(-0.2, 0.2) deg/s (on top of the board's own);
- the load cell's gain, x U(0.97, 1.03);
- battery sag: the pack's internal resistance x U(1, 2.5) and its charge at the start,
  U(0.85, 1.0).
"""

from __future__ import annotations

import math
import random
from dataclasses import asdict, dataclass, replace

from firmware_like.arena_params import LidarParams
from firmware_like.imu import ImuModel
from firmware_like.marte_params import MarteParams


@dataclass(frozen=True)
class Randomization:
    """One robot's departures from the model; names are what the summary prints."""

    skid_efficiency_scale: float = 1.0
    traction_scale: float = 1.0
    wheel_speed_scale_lf: float = 1.0
    wheel_speed_scale_lb: float = 1.0
    wheel_speed_scale_rf: float = 1.0
    wheel_speed_scale_rb: float = 1.0
    lidar_mount_yaw_deg: float = 0.0
    lidar_mount_dx_m: float = 0.0
    lidar_mount_dy_m: float = 0.0
    gyro_bias_x_dps: float = 0.0
    gyro_bias_y_dps: float = 0.0
    gyro_bias_z_dps: float = 0.0
    load_cell_gain_scale: float = 1.0
    battery_r_internal_scale: float = 1.0
    battery_initial_soc: float = 1.0

    @classmethod
    def draw(cls, seed: int) -> Randomization:
        """The seed's robot: one stream of its own, so the layout and the noise are the
        same with and without `--randomize`."""
        rng = random.Random(f"ramp-randomize:{seed}")

        def u(lo: float, hi: float) -> float:
            return round(rng.uniform(lo, hi), 6)

        return cls(
            skid_efficiency_scale=u(0.85, 1.15), traction_scale=u(0.85, 1.15),
            wheel_speed_scale_lf=u(0.95, 1.05), wheel_speed_scale_lb=u(0.95, 1.05),
            wheel_speed_scale_rf=u(0.95, 1.05), wheel_speed_scale_rb=u(0.95, 1.05),
            lidar_mount_yaw_deg=u(-1.0, 1.0), lidar_mount_dx_m=u(-0.01, 0.01),
            lidar_mount_dy_m=u(-0.01, 0.01),
            gyro_bias_x_dps=u(-0.2, 0.2), gyro_bias_y_dps=u(-0.2, 0.2),
            gyro_bias_z_dps=u(-0.2, 0.2),
            load_cell_gain_scale=u(0.97, 1.03), battery_r_internal_scale=u(1.0, 2.5),
            battery_initial_soc=u(0.85, 1.0))

    def as_dict(self) -> dict[str, float]:
        """The summary's `randomized`: a flat object of name -> value."""
        return asdict(self)

    def marte_params(self, p: MarteParams | None = None) -> MarteParams:
        p = p if p is not None else MarteParams()
        return replace(
            p, skid_efficiency=min(1.0, p.skid_efficiency * self.skid_efficiency_scale),
            traction=p.traction * self.traction_scale,
            wheel_speed_scale=(self.wheel_speed_scale_lf, self.wheel_speed_scale_lb,
                               self.wheel_speed_scale_rf, self.wheel_speed_scale_rb),
            load_cell_gain=p.load_cell_gain * self.load_cell_gain_scale,
            battery_r_internal=p.battery_r_internal * self.battery_r_internal_scale,
            initial_soc=self.battery_initial_soc)

    def lidar_params(self, lp: LidarParams) -> LidarParams:
        return replace(lp, mount_x=lp.mount_x + self.lidar_mount_dx_m,
                       mount_y=lp.mount_y + self.lidar_mount_dy_m,
                       mount_yaw=lp.mount_yaw + math.radians(self.lidar_mount_yaw_deg))

    def imu_model(self, m: ImuModel | None = None) -> ImuModel:
        m = m if m is not None else ImuModel()
        return replace(m, gyro_offset_dps=(self.gyro_bias_x_dps, self.gyro_bias_y_dps,
                                           self.gyro_bias_z_dps))
