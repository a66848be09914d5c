"""AHRS: the chassis' roll, pitch and yaw from the IMU, as a tick task (thesis 5.3.4, fig. 5.33).

MARTE's runs 1 and 4 were lost here (thesis table 5.7): a gyro that drifted tilted the gimbal
until the LIDAR missed the walls, and an IMU whose mount had shifted gave a wrong gravity
vector. This filter is built so that neither can happen silently.

- **Roll and pitch** come from a Mahony-style complementary filter: the gyro rates are
  integrated (a quaternion), and the accelerometer's gravity direction pulls the estimate back
  with gain `kp` (rad/s per unit of error). A gyro bias b can then tilt the estimate by only
  about b / kp (0.15 deg/s of drift -> 0.15 deg), so `gyro-drift` cannot tilt the gimbal.
  While the chassis accelerates hard (|specific force| away from 1 g) the accelerometer is
  not believed.
- **Yaw** is the gyro's alone (no compass in a metal arena) and drifts; the localizer corrects
  it when it is confident (`correct_yaw`), and the corrections also teach the filter the
  yaw-rate bias they reveal.
- **Gyro bias** is measured whenever the robot stands still (quiet gyro, steady 1 g, and the
  `moving` hook, odometry's, says the wheels are not turning) and subtracted.
- **The mount.** Samples are turned from the board's axes into the chassis' by `imu.mount` of
  `autonomy.yaml`, then by a learned `correction` rotation (identity until something shows the
  mount has moved).
- **Implausible gravity.** Two things reveal a shifted mount: the scan's own idea of level,
  fed by the localizer's re-leveller through `level_hint(roll, pitch, weight)`, disagreeing with
  the IMU's; and the attitude jumping while the robot is parked (a chassis on its wheels does
  not tilt by degrees while nothing drives it). Either way the difference is folded into the
  `correction` (so the gimbal and every later scan record use the corrected attitude) and
  `suspect` says that the IMU's own gravity is no longer trusted; `suspect_reason` says why.

Frames (SPEC 6.1): chassis x forward, y left, z up; roll positive left side up, pitch positive
nose down, yaw counter-clockwise (Z-Y-X Euler angles, radians). The accelerometer's sign is
handled by `ImuSample.specific_force_g` (+1 g up at rest; Phidget22 reports the opposite).
Everything happens in `tick(now, dt)` on the scheduler's thread; time is the samples' own.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from ramp.autonomy.hal.interfaces import PHIDGET_ACCEL_SIGN, Imu, ImuSample
from ramp.autonomy.mount import (
    IDENTITY,
    Mat3,
    Mount,
    Vec3,
    angle_between,
    axis_angle,
    mat_mul,
    mat_vec,
)

Quat = tuple[float, float, float, float]  # (w, x, y, z), chassis -> world
_RAD_PER_DEG = math.pi / 180.0  # as `ImuSample.gyro_rad_s` turns deg/s into rad/s


@dataclass(frozen=True)
class AhrsConfig:
    """The filter's tunables (ASSUMPTIONS chosen for a PhidgetSpatial 3/3/3 at 125 Hz)."""

    kp: float = 1.0  # rad/s per unit error: a 1 s time constant for roll/pitch
    kp_start: float = 8.0  # until settled: converge from a cold start in a fraction of a second
    accel_gate_g: float = 0.08  # ignore the accelerometer when |f| is off 1 g by more
    settle_s: float = 2.0  # still time (or 3x this in all) before `settled`
    still_gyro_dps: float = 1.0  # |rate - bias| below this on every sample of a still period
    still_accel_g: float = 0.02  # |f| within this of 1 g
    still_min_s: float = 0.5  # a still period shorter than this does not update the bias
    bias_tau_s: float = 5.0  # averaging time of the bias while still
    yaw_bias_gain: float = 0.3  # share of a yaw correction's implied rate taken into the bias
    max_bias_dps: float = 2.0  # a bias estimate is clipped to this
    parked_jump_deg: float = 1.5  # attitude change while parked that means the mount moved
    hint_adopt_deg: float = 0.7  # scan-vs-IMU level difference worth correcting
    suspect_deg: float = 2.0  # a correction this large means the IMU's gravity is wrong
    gravity_tolerance_g: float = 0.05  # still |f| this far from 1 g is implausible
    history_s: float = 3.0  # attitude kept for `attitude_at`


# -- small quaternion helpers (plain floats: one update per sample) ----------------------------
def _q_mul(a: Quat, b: Quat) -> Quat:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def _q_norm(q: Quat) -> Quat:
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def quat_from_euler(roll: float, pitch: float, yaw: float) -> Quat:
    """Rz(yaw) Ry(pitch) Rx(roll) as a quaternion."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (cy * cp * cr + sy * sp * sr, cy * cp * sr - sy * sp * cr,
            cy * sp * cr + sy * cp * sr, sy * cp * cr - cy * sp * sr)


def euler_from_quat(q: Quat) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a quaternion, Z-Y-X."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - x * z))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def up_in_chassis(roll: float, pitch: float) -> Vec3:
    """The world's up direction seen from a chassis at this roll and pitch."""
    return (-math.sin(pitch), math.cos(pitch) * math.sin(roll),
            math.cos(pitch) * math.cos(roll))


def _rotation_onto(a: Vec3, b: Vec3, share: float = 1.0) -> Mat3:
    """The smallest rotation turning direction `a` toward `b` (by `share` of the angle)."""
    axis = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    if math.sqrt(sum(c * c for c in axis)) < 1e-12:
        return IDENTITY
    return axis_angle(axis, share * angle_between(a, b))


def _rotation_angle(r: Mat3) -> float:
    return math.acos(max(-1.0, min(1.0, (r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0)))


class Ahrs:
    """Attitude from an `Imu`, updated in `tick`; read `roll`, `pitch`, `yaw`."""

    def __init__(self, imu: Imu, mount: Mount | None = None, config: AhrsConfig | None = None,
                 *, moving: Callable[[], bool] | None = None) -> None:
        self.imu = imu
        self.config = config or AhrsConfig()
        self.mount_rotation: Mat3 = (mount or Mount()).rotation()
        #: Learned turn of the IMU on its mount, chassis frame (identity while trusted).
        self.correction: Mat3 = IDENTITY
        self._to_chassis: Mat3 = self.mount_rotation
        self.moving = moving or (lambda: False)
        self._q: Quat = (1.0, 0.0, 0.0, 0.0)
        #: `euler_from_quat` of the quaternion `_euler_of` (the one object, not an equal one):
        #: the gimbal, the parked watch and the history all read the angles of one estimate.
        self._euler_of: Quat | None = None
        self._euler = (0.0, 0.0, 0.0)
        self._consts: tuple[AhrsConfig, float, float] | None = None  # (config, quiet, limit)
        self._parked_up: Vec3 = (0.0, 0.0, 1.0)  # up_in_chassis of `_parked_ref`'s angles
        self._bias = [0.0, 0.0, 0.0]  # rad/s, chassis axes
        self._bias_samples = 0.0  # seconds of stillness in the bias average so far
        self._started: float | None = None
        self._last_t: float | None = None
        self._still_since: float | None = None
        self._still_total = 0.0
        self._still_force = 1.0  # |f| averaged over about a second, in g
        self._parked_ref: tuple[float, float, float] | None = None  # (t, roll, pitch)
        self._last_yaw_fix: float | None = None
        self._times: deque[float] = deque()
        self._atts: deque[tuple[float, float, float]] = deque()
        self.samples = 0
        self.settled = False
        self.suspect = False
        self.suspect_reason = ""
        self.yaw_known = False  # a yaw was given (reset_yaw / correct_yaw) since start
        self.hints = 0  # level hints received

    # -- what the rest reads ------------------------------------------------------------------
    @property
    def roll(self) -> float:
        return self.attitude[0]

    @property
    def pitch(self) -> float:
        return self.attitude[1]

    @property
    def yaw(self) -> float:
        return self.attitude[2]

    @property
    def attitude(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) in radians now."""
        q = self._q
        if q is not self._euler_of:
            self._euler = euler_from_quat(q)
            self._euler_of = q
        return self._euler

    def roll_pitch(self) -> tuple[float, float]:
        """(roll, pitch) in radians now (what the gimbal levels on)."""
        att = self.attitude
        return att[0], att[1]

    @property
    def time(self) -> float | None:
        """Clock time of the newest sample taken in."""
        return self._last_t

    @property
    def gyro_bias(self) -> Vec3:
        """The gyro bias being subtracted, rad/s in chassis axes."""
        return (self._bias[0], self._bias[1], self._bias[2])

    @property
    def still(self) -> bool:
        return self._still_since is not None

    @property
    def correction_deg(self) -> float:
        """How far the learned mount correction turns the IMU's readings, degrees."""
        return math.degrees(_rotation_angle(self.correction))

    def attitude_at(self, t: float) -> tuple[float, float, float]:
        """(roll, pitch, yaw) at clock time `t`, interpolated in the recent history (clamped
        to its ends)."""
        times, atts = self._times, self._atts
        if not times:
            return self.attitude
        if t <= times[0]:
            return atts[0]
        if t >= times[-1]:
            return atts[-1]
        i = bisect.bisect_right(times, t)
        t0, t1 = times[i - 1], times[i]
        a, b = atts[i - 1], atts[i]
        f = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]),
                math.remainder(a[2] + f * math.remainder(b[2] - a[2], 2 * math.pi),
                               2 * math.pi))

    # -- what the localizer tells it ----------------------------------------------------------
    def reset_yaw(self, yaw: float) -> None:
        """Take `yaw` (rad) as the heading now: the start, or a trusted fix."""
        self._turn_yaw(math.remainder(yaw - self.yaw, 2 * math.pi))
        self.yaw_known = True
        self._last_yaw_fix = self._last_t

    def correct_yaw(self, yaw: float, weight: float) -> None:
        """The localizer's yaw (rad) with a confidence `weight` in 0..1: move toward it by
        that share, and learn the yaw-rate bias the error reveals. While no yaw is known yet
        (started with a start-box hint only), the first one is taken whole."""
        w = max(0.0, min(1.0, weight))
        if w == 0.0:
            return
        if not self.yaw_known:  # nothing to blend with: the first fix is the heading
            self.reset_yaw(yaw)
            return
        err = math.remainder(yaw - self.yaw, 2 * math.pi)
        self._turn_yaw(w * err)
        now = self._last_t
        if self._last_yaw_fix is not None and now is not None and self.yaw_known:
            span = now - self._last_yaw_fix
            if span > 1.0:
                rate = err / span  # the gyro read this much too high (negative: too low)
                limit = math.radians(self.config.max_bias_dps)
                self._bias[2] = max(-limit, min(limit, self._bias[2]
                                                - self.config.yaw_bias_gain * w * rate))
        self._last_yaw_fix = now
        self.yaw_known = True

    def level_hint(self, roll: float, pitch: float, weight: float,
                   t: float | None = None) -> None:
        """What the scan says the chassis' roll and pitch (rad) were at time `t` (now when
        None), with a confidence `weight` in 0..1 (the re-leveller's). A disagreement beyond
        `hint_adopt_deg` is folded into the mount correction; beyond `suspect_deg` in all, the
        IMU's gravity is `suspect`."""
        w = max(0.0, min(1.0, weight))
        self.hints += 1
        if w == 0.0:
            return
        own = self.attitude_at(t) if t is not None else self.attitude
        mine = up_in_chassis(own[0], own[1])
        theirs = up_in_chassis(roll, pitch)
        if math.degrees(angle_between(mine, theirs)) < self.config.hint_adopt_deg:
            return
        self._fold(mine, theirs, w, "the scan's level disagrees with the IMU's gravity")
        r, p, y = self.attitude
        rr, pp = own[0] + w * (roll - own[0]), own[1] + w * (pitch - own[1])
        self._q = quat_from_euler(rr + (r - own[0]), pp + (p - own[1]), y)
        self._reset_history()
        self._parked_ref = None  # the jump just made is the fix, not the IMU moving

    # -- the task ------------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        """Take in every sample the IMU collected since the last tick."""
        for s in self.imu.drain():
            self.update(s)

    def update(self, s: ImuSample) -> None:
        """One sample in (also usable without an `Imu`, e.g. from a log)."""
        cfg = self.config
        if self._last_t is None:
            self._started = s.t
            self._last_t = s.t
            self._first(s)
            return
        t = s.t
        h = t - self._last_t
        if h <= 0.0:
            return
        self._last_t = t
        # mat_vec of the chassis turn on the sample's specific force and rad/s, written out
        # (the same products and sums; `ImuSample.specific_force_g`, `gyro_rad_s`).
        (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = self._to_chassis
        a0, a1, a2 = s.accel_g
        sg = PHIDGET_ACCEL_SIGN
        v0, v1, v2 = sg * a0, sg * a1, sg * a2
        f0 = m00 * v0 + m01 * v1 + m02 * v2
        f1 = m10 * v0 + m11 * v1 + m12 * v2
        f2 = m20 * v0 + m21 * v1 + m22 * v2
        d0, d1, d2 = s.gyro_dps
        r = _RAD_PER_DEG
        v0, v1, v2 = d0 * r, d1 * r, d2 * r
        g0 = m00 * v0 + m01 * v1 + m02 * v2
        g1 = m10 * v0 + m11 * v1 + m12 * v2
        g2 = m20 * v0 + m21 * v1 + m22 * v2
        n = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        moving = self.moving()
        # Stillness: quiet gyro, steady |f| (averaged over about a second: steady, whatever
        # its value, means no shaking) and wheels at rest; a still sample feeds the bias.
        consts = self._consts
        if consts is None or consts[0] is not cfg:
            consts = self._make_constants()
        quiet_limit = consts[1]
        b = self._bias
        hs = h / 1.0
        sf = self._still_force
        sf += (n - sf) * (hs if hs < 1.0 else 1.0)  # min(1.0, h / 1.0)
        self._still_force = sf
        if (not moving and abs(g0 - b[0]) < quiet_limit and abs(g1 - b[1]) < quiet_limit
                and abs(g2 - b[2]) < quiet_limit and abs(n - sf) < cfg.still_accel_g):
            self._take_still(t, h, g0, g1, g2, consts[2])
        else:
            self._still_since = None
        b = self._bias
        wx, wy, wz = g0 - b[0], g1 - b[1], g2 - b[2]
        qw, qx, qy, qz = self._q
        if n > 0.0 and abs(n - 1.0) < cfg.accel_gate_g:
            ax, ay, az = f0 / n, f1 / n, f2 / n
            vx = 2 * (qx * qz - qw * qy)  # up, seen from the chassis, as estimated
            vy = 2 * (qy * qz + qw * qx)
            vz = qw * qw - qx * qx - qy * qy + qz * qz
            k = cfg.kp if self.settled else cfg.kp_start
            wx += k * (ay * vz - az * vy)
            wy += k * (az * vx - ax * vz)
            wz += k * (ax * vy - ay * vx)
        half = 0.5 * h
        # _q_norm(_q_mul(q, (1, wx half, wy half, wz half))), written out.
        bw, bx, by, bz = 1.0, wx * half, wy * half, wz * half
        pw = qw * bw - qx * bx - qy * by - qz * bz
        px = qw * bx + qx * bw + qy * bz - qz * by
        py = qw * by - qx * bz + qy * bw + qz * bx
        pz = qw * bz + qx * by - qy * bx + qz * bw
        nq = math.sqrt(pw * pw + px * px + py * py + pz * pz)
        self._q = (pw / nq, px / nq, py / nq, pz / nq)
        self.samples += 1
        if not self.settled and self._started is not None and (
                self._still_total >= cfg.settle_s or t - self._started >= 3 * cfg.settle_s):
            self.settled = True
        # _record(t), written out.
        q = self._q
        att = euler_from_quat(q)
        self._euler_of, self._euler = q, att
        times, atts = self._times, self._atts
        times.append(t)
        atts.append(att)
        horizon = t - cfg.history_s
        while len(times) > 2 and times[1] < horizon:
            times.popleft()
            atts.popleft()
        if not self.settled or moving:
            self._parked_ref = None
        else:
            self._watch_parked(t, att)

    # -- internals ------------------------------------------------------------------------------
    def _first(self, s: ImuSample) -> None:
        """Start from the accelerometer's roll and pitch (yaw 0 until told)."""
        f = mat_vec(self._to_chassis, s.specific_force_g)
        roll = math.atan2(f[1], f[2])
        pitch = math.atan2(-f[0], math.hypot(f[1], f[2]))
        self._q = quat_from_euler(roll, pitch, 0.0)
        self._still_force = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        self._record(s.t)

    def _turn_yaw(self, delta: float) -> None:
        half = 0.5 * delta
        self._q = _q_norm(_q_mul((math.cos(half), 0.0, 0.0, math.sin(half)), self._q))
        self._reset_history()

    def _record(self, t: float) -> None:
        times, atts = self._times, self._atts
        times.append(t)
        atts.append(self.attitude)
        horizon = t - self.config.history_s
        while len(times) > 2 and times[1] < horizon:
            times.popleft()
            atts.popleft()

    def _reset_history(self) -> None:
        """After a jump in the estimate, older entries would interpolate across it."""
        if self._last_t is not None:
            self._times.clear()
            self._atts.clear()
            self._record(self._last_t)

    def _make_constants(self) -> tuple[AhrsConfig, float, float]:
        """(config, quiet gyro limit, bias limit) in rad/s, made once per config."""
        cfg = self.config
        consts = (cfg, math.radians(cfg.still_gyro_dps), math.radians(cfg.max_bias_dps))
        self._consts = consts
        return consts

    def _take_still(self, t: float, h: float, g0: float, g1: float, g2: float,
                    limit: float) -> None:
        """A still sample (gyro g0..g2 in rad/s, chassis axes): the still clocks run, and
        once still long enough the gyro bias averages toward it (clipped to `limit`)."""
        cfg = self.config
        if self._still_since is None:
            self._still_since = t
        self._still_total += h
        if t - self._still_since < cfg.still_min_s and self._bias_samples > 0.0:
            return
        # Running mean at first, then an exponential average with time constant bias_tau_s.
        self._bias_samples += h
        k = h / min(self._bias_samples, cfg.bias_tau_s)
        bias = self._bias
        low = -limit
        for i, g in ((0, g0), (1, g1), (2, g2)):
            v = bias[i] + (g - bias[i]) * k
            v = v if v < limit else limit  # min(limit, v)
            bias[i] = v if v > low else low  # max(-limit, ...)
        if self._bias_samples > cfg.settle_s and abs(self._still_force - 1.0) > \
                cfg.gravity_tolerance_g:
            self._flag(f"gravity reads {self._still_force:.3f} g while still")

    def _watch_parked(self, t: float, att: tuple[float, float, float]) -> None:
        """A parked chassis (settled, wheels at rest) does not tilt: an attitude jump then is
        the IMU moving. `att`: the attitude just recorded."""
        roll, pitch, _ = att
        ref = self._parked_ref
        if ref is None:
            self._parked_ref = (t, roll, pitch)
            self._parked_up = up_in_chassis(roll, pitch)
            return
        _, r0, p0 = ref
        before, now = self._parked_up, up_in_chassis(roll, pitch)
        jump = math.degrees(angle_between(before, now))
        if jump < self.config.parked_jump_deg:
            return
        # Only once the IMU has stopped turning (a shift takes a fraction of a second).
        if not self.still:
            return
        self._fold(now, before, 1.0, f"attitude jumped {jump:.1f} deg while parked")
        _, _, yaw = self.attitude
        self._q = quat_from_euler(r0, p0, yaw)
        self._reset_history()
        self._parked_ref = (t, r0, p0)
        self._parked_up = before

    def _fold(self, seen: Vec3, truth: Vec3, share: float, why: str) -> None:
        """Turn the IMU's readings so that `seen` up becomes `truth` up (chassis frame)."""
        fix = _rotation_onto(seen, truth, share)
        self.correction = mat_mul(fix, self.correction)
        self._to_chassis = mat_mul(self.correction, self.mount_rotation)
        # The bias was measured in the old axes; re-express it.
        b = mat_vec(fix, (self._bias[0], self._bias[1], self._bias[2]))
        self._bias = [b[0], b[1], b[2]]
        if self.correction_deg >= self.config.suspect_deg:
            self._flag(f"{why}; correcting the IMU mount by {self.correction_deg:.1f} deg")

    def _flag(self, reason: str) -> None:
        self.suspect = True
        self.suspect_reason = reason
