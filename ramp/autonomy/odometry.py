"""Wheel odometry from the commands the autonomy sends: where `base:base.drive` moved the robot.

MARTE has no wheel encoders the autonomy can read (the Sabertooths are open loop), so the
autonomy predicts its motion from what it commanded, with the same skid-steer model the
planner uses (`ramp.autonomy.robot_model`): SPEC 2.3's mix turns `(speed %, direction deg)`
into left and right wheel percentages, each wheel follows its command with a first-order lag,
and the body moves at the mean of the two sides and turns at `skid_efficiency * (right - left)
/ track_width`. The localizer fuses these deltas between scans; they drift (slip, the rail
voltage, rocks), which is exactly why they are only a prior.

Numbers and sources (the simulator's MARTE model makes the same assumptions):
- wheel speed, track width, skid efficiency: `ramp.autonomy.robot_model.MARTE`;
- `MOTOR_TIME_CONSTANT_S` 0.15 s: `firmware_like/marte_params.py` motor_time_constant
  (ASSUMPTION there);
- `MOTOR_REF_VOLTAGE_V` 20 V: `firmware_like/marte_params.py` motor_ref_voltage: the free speed
  holds at 20 V and scales with the rail (17-21 V, thesis p.34). `set_rail_voltage` takes
  `base:battery.volt` when the mission reads it.

Pure bookkeeping on the injected clock: `command(now, ...)` when a drive is sent, `tick(now,
dt)` (or `advance(now)`) to integrate, `pose_at(t)` / `relative(t0, t1)` for the localizer.
The pose is in the odometry's own frame (x, y in metres, yaw in radians counter-clockwise),
starting at (0, 0, 0) unless `reset` puts it elsewhere.
"""

from __future__ import annotations

import bisect
import math
from collections import deque

from ramp.autonomy.robot_model import MARTE, RobotModel, wheel_mix

MOTOR_TIME_CONSTANT_S = 0.15  # firmware_like/marte_params.py motor_time_constant (ASSUMPTION)
MOTOR_REF_VOLTAGE_V = 20.0  # firmware_like/marte_params.py motor_ref_voltage (ASSUMPTION)
MAX_PIECE_S = 0.01  # integration step: the heading changes by < 0.5 deg in one at full spin

Pose2 = tuple[float, float, float]
_TWO_PI = 2.0 * math.pi


def compose(a: Pose2, b: Pose2) -> Pose2:
    """Pose `b` (expressed in the frame of `a`) in the frame `a` is expressed in."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1],
            math.remainder(a[2] + b[2], 2.0 * math.pi))


def between(a: Pose2, b: Pose2) -> Pose2:
    """Pose `b` seen from pose `a` (both in one frame): the motion from a to b."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, math.remainder(b[2] - a[2], 2.0 * math.pi))


class Odometry:
    """Dead reckoning from drive commands, with a short history for scans taken in between."""

    def __init__(self, model: RobotModel = MARTE, *, now: float = 0.0,
                 motor_time_constant_s: float = MOTOR_TIME_CONSTANT_S,
                 history_s: float = 30.0) -> None:
        if motor_time_constant_s < 0.0 or history_s <= 0.0:
            raise ValueError("odometry: time constant must be >= 0 and history > 0")
        self.model = model
        self.tau = motor_time_constant_s
        self.history_s = history_s
        self.speed_scale = 1.0  # rail voltage / MOTOR_REF_VOLTAGE_V
        self._t = now
        self._pose: Pose2 = (0.0, 0.0, 0.0)
        self._target = (0.0, 0.0)  # wheel percentages commanded (left, right)
        self._wheels = (0.0, 0.0)  # wheel percentages the motors have reached
        self._times: deque[float] = deque([now])
        self._poses: deque[Pose2] = deque([self._pose])
        self.distance_m = 0.0  # path length driven, for diagnostics
        #: (h, tau, decay, frac) of the last piece: the wheel lag of a step, kept while the
        #: step and the time constant repeat (a pure function of the two).
        self._lag = (math.nan, math.nan, 0.0, 0.0)

    # -- commands -----------------------------------------------------------------------------
    def command(self, now: float, speed: float, direction_deg: float) -> None:
        """A `base:base.drive=(speed,direction)` was accepted at `now`."""
        self.wheels(now, *wheel_mix(speed, direction_deg))

    def wheels(self, now: float, left_pct: float, right_pct: float) -> None:
        """Left and right wheel percentages commanded at `now` (`*_wheel.vel`)."""
        self.advance(now)
        clamp = lambda v: max(-100.0, min(100.0, float(v)))  # noqa: E731
        self._target = (clamp(left_pct), clamp(right_pct))

    def stop(self, now: float) -> None:
        """A stop (ours, the operator's, the watchdog's): the wheels spin down."""
        self.wheels(now, 0.0, 0.0)

    def set_rail_voltage(self, volts: float) -> None:
        """The battery's voltage (`base:battery.volt`): motor speed scales with it."""
        if math.isfinite(volts) and volts > 0.0:
            self.speed_scale = volts / MOTOR_REF_VOLTAGE_V

    def reset(self, now: float, pose: Pose2 = (0.0, 0.0, 0.0)) -> None:
        """Start again from `pose` (history is forgotten; wheel speeds are kept)."""
        self.advance(now)
        self._pose = pose
        self._times = deque([now])
        self._poses = deque([pose])

    # -- integration --------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        self.advance(now)

    def advance(self, now: float) -> None:
        """Integrate the motion up to `now`."""
        h_total = now - self._t
        if h_total <= 0.0:
            return
        pieces = max(1, math.ceil(h_total / MAX_PIECE_S - 1e-9))
        h = h_total / pieces
        for _ in range(pieces):
            self._piece(h)
        self._t = now
        times, poses = self._times, self._poses
        times.append(now)
        poses.append(self._pose)
        history_s = self.history_s
        while len(times) > 2 and now - times[1] > history_s:
            times.popleft()
            poses.popleft()

    def _piece(self, h: float) -> None:
        """Exact wheel lag over `h`; the mean wheel speed moves the body along the mid
        heading."""
        (l0, r0), (lt, rt) = self._wheels, self._target
        tau = self.tau
        lag = self._lag
        if lag[0] == h and lag[1] == tau:  # the same step as last time: the same numbers
            decay, frac = lag[2], lag[3]
        else:
            decay = math.exp(-h / tau) if tau > 0.0 else 0.0
            # Integral of target + (s0 - target) e^(-t/tau) over h, divided by h.
            frac = (tau * (1.0 - decay) / h) if tau > 0.0 else 0.0
            self._lag = (h, tau, decay, frac)
        l_mean = lt + (l0 - lt) * frac
        r_mean = rt + (r0 - rt) * frac
        self._wheels = (lt + (l0 - lt) * decay, rt + (r0 - rt) * decay)
        scale = self.speed_scale
        v, w = self.model.body_velocity(l_mean * scale, r_mean * scale)
        x, y, yaw = self._pose
        mid = yaw + 0.5 * w * h
        self._pose = (x + v * math.cos(mid) * h, y + v * math.sin(mid) * h,
                      math.remainder(yaw + w * h, _TWO_PI))
        self.distance_m += abs(v) * h

    # -- what the localizer reads -------------------------------------------------------------
    @property
    def pose(self) -> Pose2:
        """The dead-reckoned pose as of the last `advance`."""
        return self._pose

    @property
    def moving(self) -> bool:
        """A wheel is commanded or still spinning down (more than 0.5 %)."""
        return self.is_moving()

    def is_moving(self) -> bool:
        """`moving` as a call (the AHRS's hook asks it for every IMU sample)."""
        lt, rt = self._target
        lw, rw = self._wheels
        return abs(lt) > 0.5 or abs(rt) > 0.5 or abs(lw) > 0.5 or abs(rw) > 0.5

    def pose_at(self, t: float) -> Pose2:
        """The pose at clock time `t`, interpolated in the history (clamped to its ends)."""
        times, poses = self._times, self._poses
        if t <= times[0]:
            return poses[0]
        if t >= times[-1]:
            return poses[-1]
        i = bisect.bisect_right(times, t)
        t0, t1 = times[i - 1], times[i]
        a, b = poses[i - 1], poses[i]
        f = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]),
                math.remainder(a[2] + f * math.remainder(b[2] - a[2], 2.0 * math.pi),
                               2.0 * math.pi))

    def relative(self, t0: float, t1: float) -> Pose2:
        """The motion from time t0 to t1, in the robot's frame at t0: (forward m, left m,
        turn rad)."""
        return between(self.pose_at(t0), self.pose_at(t1))
