"""A PhidgetSpatial 3/3/3 strapped to the chassis: what its SpatialData events would say.

USB cannot be emulated, so this is a HAL-level emulator (SPEC 6.2): the `sim` IMU driver polls
it, where the `phidget` driver would drain libphidget22's events. It reads the chassis' true
motion from `truth()` and produces, every data interval on the injected clock, what the board
would measure there:

- **Truth contract.** `truth()` returns an object with `roll`, `pitch`, `yaw` (rad, ZYX Euler,
  SPEC 6.1's frame: x forward, y left, z up, yaw counter-clockwise), `omega_body` (rad/s,
  3 numbers, chassis axes) and `accel_body` (m/s^2, 3 numbers, chassis axes, the chassis
  origin's acceleration WITHOUT gravity). The arena world exposes it as `world.imu_truth()`.
  Between two polls the truth is interpolated linearly, so samples at 8 ms stay smooth when
  the world is stepped at 10 ms.
- **Physics.** Specific force at the board = acceleration of its mounting point (lever arm:
  alpha x r + omega x (omega x r)) minus gravity; both it and the rate are turned into the
  board's axes by its mount rotation (`autonomy.yaml` `imu.mount`).
- **The board's conventions.** Acceleration in g with Phidget22's sign (minus the specific
  force: (0, 0, -1) g lying level at rest), angular rate in deg/s, magnetic field in gauss,
  timestamp in ms restarting at every attach.
- **Errors.** White noise on every axis, a constant bias per seed, saturation at the board's
  ranges. Numbers from the PhidgetSpatial Precision 3/3/3 (1044) data sheet where it gives
  them, else ASSUMPTION (see `ImuModel`).
- **Faults (SPEC 6.2, chosen by name, seeded):** `gyro-drift`, a gyro bias that wanders away
  from its start-up value (several deg/min when integrated alone: what drifted MARTE's AHRS in
  run 1); `imu-shift`, the mount rotating 4-8 deg about a horizontal axis at a moment chosen
  from the seed (what tilted MARTE's LIDAR in run 4). `fault_info()` says what was chosen.

Deterministic: the same seed, clock steps and truth give the same samples, however the
polls fall (noise is drawn per sample from its own stream).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

import numpy as np

GRAVITY_MPS2 = 9.80665
#: Phidget22 reports acceleration as minus the specific force (ROS's phidgets_spatial negates
#: it to get REP 145's +1 g up).
PHIDGET_ACCEL_SIGN = -1.0

FAULTS = ("none", "gyro-drift", "imu-shift")

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]


class Clock(Protocol):
    """Anything with `now() -> float` (ramp.clock.VirtualClock, MonotonicClock)."""

    def now(self) -> float: ...


@dataclass(frozen=True)
class ImuTruth:
    """A ready-made truth value (tests, simple worlds); any object with these fields works."""

    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    omega_body: Vec3 = (0.0, 0.0, 0.0)
    accel_body: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ImuModel:
    """The board's error model and ranges."""

    accel_noise_g: float = 0.00028  # 1044 data sheet: accelerometer white noise sigma 280 ug
    gyro_noise_dps: float = 0.095  # 1044 data sheet: gyroscope white noise sigma 0.095 deg/s
    mag_noise_gauss: float = 0.0011  # ASSUMPTION: 1.1 mG (phidgets_drivers' default stdev)
    accel_bias_g: float = 0.002  # ASSUMPTION: sigma of the constant bias per board (seed)
    gyro_bias_dps: float = 0.05  # ASSUMPTION: sigma of the constant bias left after factory cal
    gyro_offset_dps: Vec3 = (0.0, 0.0, 0.0)  # a constant bias added to it (--randomize)
    accel_range_g: float = 8.0  # 1042 (3/3/3): +-8 g
    gyro_range_dps: float = 2000.0  # 1042 (3/3/3): +-2000 deg/s
    #: ASSUMPTION: Earth's field in the arena frame, gauss (Florida: ~0.24 G horizontal, ~0.41
    #: G down; the arena's +x taken as magnetic north). None: a board without a compass.
    earth_field_gauss: Vec3 | None = (0.24, 0.0, -0.41)
    # gyro-drift: each axis' bias leaves its start-up value for a mean drawn in
    # [drift_min_dps, drift_max_dps] (random sign) with time constant drift_tau_s, wandering
    # around it by drift_wander_dps (ASSUMPTION: tuned so that the rate integrates to several
    # degrees per minute, as in MARTE's run 1).
    drift_min_dps: float = 0.08
    drift_max_dps: float = 0.15
    drift_tau_s: float = 30.0
    drift_wander_dps: float = 0.02
    # imu-shift: the angle range of SPEC 6.2 and how long the mount takes to move
    shift_min_deg: float = 4.0
    shift_max_deg: float = 8.0
    shift_duration_s: float = 0.2  # ASSUMPTION: a damper giving way is quick, not instant
    zero_gyro_s: float = 2.0  # Phidget22 zeroGyro: "re-zeros the gyroscope in 1-2 seconds"


class SpatialData(NamedTuple):
    """One SpatialData event, as Phidget22 hands it to the handler, plus the clock time."""

    t: float  # s on the emulator's clock when it was measured
    timestamp_ms: float
    acceleration: Vec3  # g, Phidget22 sign
    angular_rate: Vec3  # deg/s
    magnetic_field: Vec3 | None  # gauss


class _Snap(NamedTuple):
    t: float
    roll: float
    pitch: float
    yaw: float
    omega: Vec3
    accel: Vec3


class ImuEmulator:
    """The board; `poll()` returns the samples measured since the last poll."""

    NOISE_PER_SAMPLE = 12  # accel 3, gyro 3, compass 3, drift wander 3
    MIN_INTERVAL_MS = 1
    MAX_INTERVAL_MS = 1000

    def __init__(self, clock: Clock, truth: Callable[[], Any], *, seed: int = 0,
                 fault: str | None = None, data_interval_ms: int = 8, mount: Any = None,
                 model: ImuModel | None = None,
                 shift_window_s: tuple[float, float] = (60.0, 480.0)) -> None:
        fault = fault or "none"
        if fault not in FAULTS:
            raise ValueError(f"unknown IMU fault {fault!r} (expected one of: {', '.join(FAULTS)})")
        self.clock = clock
        self.truth = truth
        self.seed = seed
        self.fault = fault
        self.model = model or ImuModel()
        self.started_at = float(clock.now())
        self._interval_ms = self._check_interval(data_interval_ms)
        m = mount
        self.lever: Vec3 = (float(getattr(m, "x", 0.0)), float(getattr(m, "y", 0.0)),
                            float(getattr(m, "z", 0.0)))
        self.mount_rotation: Mat3 = _rot_zyx(math.radians(getattr(m, "roll", 0.0)),
                                             math.radians(getattr(m, "pitch", 0.0)),
                                             math.radians(getattr(m, "yaw", 0.0)))
        params_seq, noise_seq = np.random.SeedSequence(seed).spawn(2)
        prng = np.random.default_rng(params_seq)
        md = self.model
        self.accel_bias_g: Vec3 = _vec(prng.normal(0.0, md.accel_bias_g, 3))
        self.gyro_bias_dps: Vec3 = _vec(prng.normal(0.0, md.gyro_bias_dps, 3)
                                        + np.asarray(md.gyro_offset_dps))
        # Fault parameters are drawn whatever the fault, so a seed means the same board.
        signs = prng.choice((-1.0, 1.0), 3)
        mags = prng.uniform(md.drift_min_dps, md.drift_max_dps, 3)
        self.drift_mean_dps: Vec3 = _vec(signs * mags)
        lo, hi = shift_window_s
        if not 0.0 <= lo <= hi:
            raise ValueError(f"shift window {shift_window_s} must be 0 <= start <= end")
        self.shift_at_s = self.started_at + float(prng.uniform(lo, hi))
        self.shift_deg = float(prng.uniform(md.shift_min_deg, md.shift_max_deg))
        azimuth = float(prng.uniform(0.0, 2.0 * math.pi))
        self.shift_axis: Vec3 = (math.cos(azimuth), math.sin(azimuth), 0.0)
        self._shifted: Mat3 | None = None  # the mount once the shift is over
        self._shift_on = False  # a shift was injected (`shift_now`), whatever the fault
        self._noise_rng = np.random.default_rng(noise_seq)
        self._noise: list[float] = []  # plain floats: same values, faster to index than numpy
        self._noise_at = 0
        self._drift: list[float] = [0.0, 0.0, 0.0]
        self._gyro_correction: list[float] = [0.0, 0.0, 0.0]
        self._zeroing: tuple[float, list[float], int] | None = None  # (until, sum, count)
        self.attached = True
        # The sample grid: sample k of the grid is measured at grid_t + k * interval and
        # stamped grid_ms + k * interval_ms (the board's timestamp restarts at each attach).
        self._grid_t = self.started_at
        self._grid_ms = 0.0
        self._k = 0
        self._prev: _Snap | None = None
        self.samples = 0

    # -- what the driver can do to the board -------------------------------------------------
    def set_data_interval(self, ms: int) -> None:
        """Phidget22 `setDataInterval`: the next sample comes one new interval after the last."""
        ms = self._check_interval(ms)
        self._grid_t += self._k * self._interval_ms / 1000.0
        self._grid_ms += self._k * self._interval_ms
        self._k = 0
        self._interval_ms = ms

    def zero_gyro(self) -> None:
        """Phidget22 `zeroGyro`: average the rate for ~2 s and take it as the new zero."""
        self._zeroing = (float(self.clock.now()) + self.model.zero_gyro_s, [0.0, 0.0, 0.0], 0)

    def unplug(self) -> None:
        """The USB cable comes out: no more samples."""
        self.attached = False

    def plug(self) -> None:
        """The cable goes back in: the board restarts its timestamp and its default interval
        is whatever the driver sets again."""
        if self.attached:
            return
        self.attached = True
        self._grid_t = float(self.clock.now())
        self._grid_ms = 0.0
        self._k = 0
        self._prev = None

    # -- injected from outside (a trainer, a test) ---------------------------------------------
    def shift_now(self, deg: float) -> None:
        """The mount rotates `deg` degrees about the seeded horizontal axis, starting now, as
        an `imu-shift` does (taking `shift_duration_s`). A shift that had begun is completed
        into the mount first, so shifts add up; the seeded one, if still to come, is
        replaced by this one."""
        if self.shift_fraction(float(self.clock.now())) > 0.0:
            turn = _axis_angle(self.shift_axis, math.radians(self.shift_deg))
            self.mount_rotation = _mat_mul(turn, self.mount_rotation)
        self._shift_on = True
        self.shift_at_s = float(self.clock.now())
        self.shift_deg = float(deg)
        self._shifted = None

    # -- what the fault did ------------------------------------------------------------------
    def shift_fraction(self, t: float) -> float:
        """How far the imu-shift has gone at clock time t: 0 before, 1 after."""
        if not (self._shift_on or self.fault == "imu-shift") or t <= self.shift_at_s:
            return 0.0
        return min(1.0, (t - self.shift_at_s) / self.model.shift_duration_s)

    def fault_info(self) -> dict[str, Any]:
        """What the seed chose, for tests and the trace header."""
        info: dict[str, Any] = {"fault": self.fault, "seed": self.seed}
        if self.fault == "imu-shift":
            info.update(at_s=round(self.shift_at_s - self.started_at, 3),
                        deg=round(self.shift_deg, 3),
                        axis=[round(a, 4) for a in self.shift_axis])
        elif self.fault == "gyro-drift":
            info.update(drift_dps=[round(d, 4) for d in self.drift_mean_dps],
                        tau_s=self.model.drift_tau_s)
        return info

    # -- sampling ----------------------------------------------------------------------------
    @property
    def data_interval_ms(self) -> int:
        return self._interval_ms

    def poll(self) -> list[SpatialData]:
        """Every sample whose time has come since the last poll, oldest first."""
        now = float(self.clock.now())
        if not self.attached:
            return []
        snap = self._snapshot(now)
        prev = self._prev if self._prev is not None and self._prev.t < now else None
        out: list[SpatialData] = []
        step_s = self._interval_ms / 1000.0
        while True:
            ts = self._grid_t + (self._k + 1) * step_s
            if ts > now + 1e-9:
                break
            self._k += 1
            ms = self._grid_ms + self._k * self._interval_ms
            out.append(self._measure(ts, ms, prev, snap))
        if prev is None or snap.t > prev.t:
            self._prev = snap
        return out

    def _check_interval(self, ms: int) -> int:
        if isinstance(ms, bool) or not isinstance(ms, int) \
                or not self.MIN_INTERVAL_MS <= ms <= self.MAX_INTERVAL_MS:
            raise ValueError(f"data interval {ms!r} ms is outside "
                             f"{self.MIN_INTERVAL_MS}-{self.MAX_INTERVAL_MS}")
        return ms

    def _snapshot(self, now: float) -> _Snap:
        tr = self.truth()
        w, a = tr.omega_body, tr.accel_body  # `_vec` of each, written out
        return _tuple_new(_Snap, (now, float(tr.roll), float(tr.pitch), float(tr.yaw),
                                  (float(w[0]), float(w[1]), float(w[2])),
                                  (float(a[0]), float(a[1]), float(a[2]))))

    def _measure(self, ts: float, ms: float, prev: _Snap | None, cur: _Snap) -> SpatialData:
        # The vector helpers below (_lerp, _cross, _mat_t_vec, ...) are written out here, each
        # sum in the helper's own order: this runs 125 times a simulated second.
        md = self.model
        # Chassis motion at ts, interpolated between the last two truths.
        if prev is None:
            roll, pitch, yaw = cur.roll, cur.pitch, cur.yaw
            (w0, w1, w2), (c0, c1, c2) = cur.omega, cur.accel
            al0 = al1 = al2 = 0.0
        else:
            span = cur.t - prev.t
            # min(1.0, max(0.0, x)) as two comparisons (they pick the same value), and
            # `_wrap` written out.
            f = (ts - prev.t) / span
            f = f if f > 0.0 else 0.0
            f = f if f < 1.0 else 1.0
            roll = prev.roll + f * ((cur.roll - prev.roll + _PI) % _TWO_PI - _PI)
            pitch = prev.pitch + f * ((cur.pitch - prev.pitch + _PI) % _TWO_PI - _PI)
            yaw = prev.yaw + f * ((cur.yaw - prev.yaw + _PI) % _TWO_PI - _PI)
            (p0, p1, p2), (q0, q1, q2) = prev.omega, cur.omega
            w0, w1, w2 = p0 + f * (q0 - p0), p1 + f * (q1 - p1), p2 + f * (q2 - p2)
            (a0, a1, a2), (b0, b1, b2) = prev.accel, cur.accel
            c0, c1, c2 = a0 + f * (b0 - a0), a1 + f * (b1 - a1), a2 + f * (b2 - a2)
            inv = 1.0 / span
            al0, al1, al2 = (q0 - p0) * inv, (q1 - p1) * inv, (q2 - p2) * inv
        # Specific force at the mounting point, chassis axes: a + alpha x r + w x (w x r) - g.
        r0, r1, r2 = self.lever
        x0, x1, x2 = w1 * r2 - w2 * r1, w2 * r0 - w0 * r2, w0 * r1 - w1 * r0  # w x r
        sr, cr = math.sin(roll), math.cos(roll)
        sp, cp = math.sin(pitch), math.cos(pitch)
        # world +z seen from the chassis (ZYX) is (-sp, sr cp, cr cp)
        force = (c0 + ((al1 * r2 - al2 * r1) + (w1 * x2 - w2 * x1)) + -sp * GRAVITY_MPS2,
                 c1 + ((al2 * r0 - al0 * r2) + (w2 * x0 - w0 * x2)) + sr * cp * GRAVITY_MPS2,
                 c2 + ((al0 * r1 - al1 * r0) + (w0 * x1 - w1 * x0)) + cr * cp * GRAVITY_MPS2)
        # The board's axes: mount rotation, turned further by an imu-shift once it happens.
        rot = self.mount_rotation
        rate: Vec3 = (w0, w1, w2)
        # `shift_fraction` is 0 without a shift to come: no call then.
        frac = self.shift_fraction(ts) if self._shift_on or self.fault == "imu-shift" else 0.0
        if frac >= 1.0:
            if self._shifted is None:
                turn = _axis_angle(self.shift_axis, math.radians(self.shift_deg))
                self._shifted = _mat_mul(turn, rot)
            rot = self._shifted
        elif frac > 0.0:  # the board is turning on its mount: the gyro feels it too
            theta = math.radians(self.shift_deg)
            rot = _mat_mul(_axis_angle(self.shift_axis, theta * frac), rot)
            rate = _add(rate, _scale(self.shift_axis, theta / md.shift_duration_s))
        (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = rot
        f0, f1, f2 = force
        g0, g1, g2 = rate
        # `_draw`, written out
        at, k = self._noise_at, self.NOISE_PER_SAMPLE
        if at + k > len(self._noise):
            self._noise = self._noise_rng.standard_normal(k * 512).tolist()
            at = 0
        n = self._noise[at:at + k]
        self._noise_at = at + k
        if self.fault == "gyro-drift":
            self._advance_drift(n[9:12])
        # force and rate in the board's axes (rot transposed), to g and deg/s, with the
        # board's bias and noise, clipped at its ranges: `_clip` (max(-hi, min(hi, x))) as
        # two comparisons, which pick the same value.
        hi = float(md.accel_range_g)
        lo = -hi
        anoise, abias = md.accel_noise_g, self.accel_bias_g
        x0 = PHIDGET_ACCEL_SIGN * (m00 * f0 + m10 * f1 + m20 * f2) / GRAVITY_MPS2 + abias[0] \
            + anoise * n[0]
        x1 = PHIDGET_ACCEL_SIGN * (m01 * f0 + m11 * f1 + m21 * f2) / GRAVITY_MPS2 + abias[1] \
            + anoise * n[1]
        x2 = PHIDGET_ACCEL_SIGN * (m02 * f0 + m12 * f1 + m22 * f2) / GRAVITY_MPS2 + abias[2] \
            + anoise * n[2]
        x0 = x0 if x0 < hi else hi
        x1 = x1 if x1 < hi else hi
        x2 = x2 if x2 < hi else hi
        accel_g = (x0 if x0 > lo else lo, x1 if x1 > lo else lo, x2 if x2 > lo else lo)
        gnoise, gbias, drift = md.gyro_noise_dps, self.gyro_bias_dps, self._drift
        raw_gyro = [
            math.degrees(m00 * g0 + m10 * g1 + m20 * g2) + gbias[0] + drift[0] + gnoise * n[3],
            math.degrees(m01 * g0 + m11 * g1 + m21 * g2) + gbias[1] + drift[1] + gnoise * n[4],
            math.degrees(m02 * g0 + m12 * g1 + m22 * g2) + gbias[2] + drift[2] + gnoise * n[5]]
        if self._zeroing is not None:
            self._zero_step(ts, raw_gyro)
        hi = float(md.gyro_range_dps)
        lo = -hi
        corr = self._gyro_correction
        x0, x1, x2 = raw_gyro[0] - corr[0], raw_gyro[1] - corr[1], raw_gyro[2] - corr[2]
        x0 = x0 if x0 < hi else hi
        x1 = x1 if x1 < hi else hi
        x2 = x2 if x2 < hi else hi
        gyro = (x0 if x0 > lo else lo, x1 if x1 > lo else lo, x2 if x2 > lo else lo)
        mag: Vec3 | None = None
        if md.earth_field_gauss is not None:
            # The field in the chassis' axes (_rot_zyx(roll, pitch, yaw) transposed), then
            # in the board's.
            e0, e1, e2 = md.earth_field_gauss
            cy, sy = math.cos(yaw), math.sin(yaw)
            h0 = cy * cp * e0 + sy * cp * e1 + -sp * e2
            h1 = (cy * sp * sr - sy * cr) * e0 + (sy * sp * sr + cy * cr) * e1 + cp * sr * e2
            h2 = (cy * sp * cr + sy * sr) * e0 + (sy * sp * cr - cy * sr) * e1 + cp * cr * e2
            mnoise = md.mag_noise_gauss
            mag = (m00 * h0 + m10 * h1 + m20 * h2 + mnoise * n[6],
                   m01 * h0 + m11 * h1 + m21 * h2 + mnoise * n[7],
                   m02 * h0 + m12 * h1 + m22 * h2 + mnoise * n[8])
        self.samples += 1
        return _tuple_new(SpatialData, (ts, ms, accel_g, gyro, mag))

    def _advance_drift(self, w: Any) -> None:
        """One step of a first-order Gauss-Markov bias pulled toward `drift_mean_dps`."""
        md = self.model
        phi = math.exp(-self._interval_ms / 1000.0 / md.drift_tau_s)
        sigma = md.drift_wander_dps * math.sqrt(1.0 - phi * phi)
        for i in range(3):
            mean = self.drift_mean_dps[i]
            self._drift[i] = mean + (self._drift[i] - mean) * phi + sigma * float(w[i])

    def _zero_step(self, ts: float, raw_gyro: list[float]) -> None:
        if self._zeroing is None:
            return
        until, total, count = self._zeroing
        if ts <= until:
            self._zeroing = (until, [total[i] + raw_gyro[i] for i in range(3)], count + 1)
            return
        if count:
            self._gyro_correction = [total[i] / count for i in range(3)]
        self._zeroing = None

    def _draw(self) -> Any:
        if self._noise_at + self.NOISE_PER_SAMPLE > len(self._noise):
            self._noise = self._noise_rng.standard_normal(self.NOISE_PER_SAMPLE * 512).tolist()
            self._noise_at = 0
        n = self._noise[self._noise_at:self._noise_at + self.NOISE_PER_SAMPLE]
        self._noise_at += self.NOISE_PER_SAMPLE
        return n


#: What a NamedTuple's generated `__new__` calls, without that Python-level call (the same
#: tuple, built twice per sample).
_tuple_new = tuple.__new__


# -- small vector helpers (plain floats: a few per sample, faster than numpy at this size) ----
def _vec(v: Any) -> Vec3:
    return (float(v[0]), float(v[1]), float(v[2]))


def _add(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _scale(a: Vec3, k: float) -> Vec3:
    return (a[0] * k, a[1] * k, a[2] * k)


def _lerp(a: Vec3, b: Vec3, f: float) -> Vec3:
    return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))


def _cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


_PI = math.pi
_TWO_PI = 2.0 * math.pi


def _wrap(angle: float) -> float:
    return (angle + _PI) % _TWO_PI - _PI


def _clip(x: float, limit: float) -> float:
    return max(-limit, min(limit, x))


def _rot_zyx(roll: float, pitch: float, yaw: float) -> Mat3:
    """Rz(yaw) Ry(pitch) Rx(roll): body axes -> parent axes."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return ((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
            (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
            (-sp, cp * sr, cp * cr))


def _axis_angle(axis: Vec3, angle: float) -> Mat3:
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return ((t * x * x + c, t * x * y - s * z, t * x * z + s * y),
            (t * x * y + s * z, t * y * y + c, t * y * z - s * x),
            (t * x * z - s * y, t * y * z + s * x, t * z * z + c))


def _mat_mul(a: Mat3, b: Mat3) -> Mat3:
    return tuple(  # type: ignore[return-value]
        tuple(sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)) for i in range(3))


def _mat_t_vec(a: Mat3, v: Vec3) -> Vec3:
    """a transposed times v: a parent-frame vector seen in the body frame."""
    return (a[0][0] * v[0] + a[1][0] * v[1] + a[2][0] * v[2],
            a[0][1] * v[0] + a[1][1] * v[1] + a[2][1] * v[2],
            a[0][2] * v[0] + a[1][2] * v[1] + a[2][2] * v[2])
