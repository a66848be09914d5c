"""The autonomy's hardware interfaces: an IMU, and a pan/tilt gimbal of two RC servos.

The same shape as the backend's HAL (which the autonomy never imports): template base
classes whose public methods validate, record and log, while drivers implement the
`_`-prefixed hooks; lifecycle `open(now)`, `tick(now, dt)` on the scheduler's thread, and an
idempotent `close()`. Nothing here blocks and nothing raises from `tick` for a device that
comes and goes: a USB board that is unplugged sets `fault` (a DeviceError naming the device)
and clears it when it attaches again, so the mission can stop and wait instead of crashing.

Units are the vendor's, as Phidget22 reports them, so a log of samples reads like the
board's own: acceleration in g, angular rate in deg/s, magnetic field in gauss, all in the
sensor's own axes; servo positions in degrees of the gimbal (0 = straight ahead / level, pan
positive to the left, tilt positive nose down; see `ramp.autonomy.mount`).
"""

from __future__ import annotations

import logging
import math
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass
from typing import ClassVar

from ramp.autonomy.config import GimbalConfig, ImuConfig, ServoConfig
from ramp.errors import DeviceError

log = logging.getLogger("ramp.autonomy.hal")

Vec3 = tuple[float, float, float]

GRAVITY_MPS2 = 9.80665  # standard gravity: Phidget22's "g"

#: Phidget22's Spatial reports acceleration as minus the specific force: a board lying level
#: at rest reads (0, 0, -1) g. ROS's phidgets_spatial driver negates all three axes to get
#: REP 145's +1 g up (ros-drivers/phidgets_drivers, spatial_ros_i.cpp). `ImuSample` keeps the
#: board's numbers and offers `specific_force_g` for the physics sign.
PHIDGET_ACCEL_SIGN = -1.0

#: Fastest and hardest gimbal commands accepted (a Hitec HS-5645MG turns about 260-330 deg/s).
MAX_VELOCITY_DPS = 2000.0
MAX_ACCELERATION_DPS2 = 100000.0


_NUMBER = (int, float)  # as `int | float`, made once (checked on every gimbal command)


def _finite(value: object, what: str, label: str) -> float:
    if type(value) is float and math.isfinite(value):  # the usual case, checked first
        return value
    if isinstance(value, bool) or not isinstance(value, _NUMBER) or not math.isfinite(value):
        raise ValueError(f"{label}: {what} must be a finite number, got {value!r}")
    return float(value)


# -- common lifecycle --------------------------------------------------------------------------
class Device(ABC):
    """Open / tick / close, attach timeout and fault bookkeeping shared by every device."""

    #: The name `autonomy.yaml` uses in `driver:`.
    driver_name: ClassVar[str] = ""

    def __init__(self, name: str, attach_timeout_s: float) -> None:
        self.name = name
        self.attach_timeout_s = attach_timeout_s
        self.is_open = False
        #: The current problem (detached, never attached, silent), or None when healthy.
        self.fault: DeviceError | None = None
        self._opened_at = 0.0

    @property
    @abstractmethod
    def attached(self) -> bool:
        """True while the board is there and answering."""

    def ready(self) -> bool:
        """Open, attached and without a fault: safe to rely on."""
        return self.is_open and self.attached and self.fault is None

    def open(self, now: float) -> None:
        """Start talking to the device. Returns at once; the attach comes later (`tick`).
        Raises DeviceError only when it cannot even try (vendor library missing)."""
        if self.is_open:
            return
        self.fault = None
        self._opened_at = now
        self._open(now)
        self.is_open = True

    def tick(self, now: float, dt: float) -> None:
        """Collect what the device sent since the last tick and push pending commands."""
        if not self.is_open:
            return
        self._tick(now, dt)
        if not self.attached and self.fault is None \
                and now - self._opened_at > self.attach_timeout_s:
            self._set_fault(self._not_attached_error())

    def close(self) -> None:
        """Let go of the device; safe to call twice."""
        if not self.is_open:
            return
        self.is_open = False
        try:
            self._close()
        except Exception as exc:  # noqa: BLE001 - closing must always finish
            log.error("%s: error while closing: %s", self.name, exc)

    def _set_fault(self, err: DeviceError) -> None:
        if self.fault is None or str(self.fault) != str(err):
            log.warning("%s", err)
        self.fault = err

    def _clear_fault(self) -> None:
        if self.fault is not None:
            log.info("%s: healthy again (was: %s)", self.name, self.fault.detail)
        self.fault = None

    def _not_attached_error(self) -> DeviceError:
        return DeviceError(self.name, f"not attached within {self.attach_timeout_s:g} s - "
                           "check the USB cable and the serial number")

    @abstractmethod
    def _open(self, now: float) -> None: ...

    @abstractmethod
    def _tick(self, now: float, dt: float) -> None: ...

    @abstractmethod
    def _close(self) -> None: ...

    def __enter__(self) -> Device:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- IMU ---------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class ImuSample:
    """One reading of a PhidgetSpatial, in the board's own axes and units."""

    t: float  # s on the scheduler's clock when it was measured
    timestamp_ms: float  # the board's own timestamp (restarts from 0 at every attach)
    accel_g: Vec3  # as Phidget22 reports it: minus the specific force, in g
    gyro_dps: Vec3  # angular rate, deg/s, right-hand rule about each axis
    mag_gauss: Vec3 | None = None  # magnetic field, when the board has and reports one

    @property
    def specific_force_g(self) -> Vec3:
        """What the accelerometer feels, physics sign: +1 g up when at rest."""
        s = PHIDGET_ACCEL_SIGN
        return (s * self.accel_g[0], s * self.accel_g[1], s * self.accel_g[2])

    @property
    def gyro_rad_s(self) -> Vec3:
        r = math.pi / 180.0
        return (self.gyro_dps[0] * r, self.gyro_dps[1] * r, self.gyro_dps[2] * r)


class Imu(Device):
    """A 3-axis accelerometer + gyroscope (+ compass) board, sampled at a fixed interval.

    The driver collects every sample the board sends; `drain()` hands them over in order,
    each exactly once, so an attitude filter integrates every gyro reading. A reader that
    falls behind loses the oldest samples (counted in `dropped`), never the newest.
    """

    MAX_BUFFER = 4096  # samples kept for a slow reader (about 33 s at 8 ms)

    def __init__(self, config: ImuConfig, name: str = "imu") -> None:
        super().__init__(name, config.attach_timeout_s)
        self.config = config
        self.data_interval_ms = config.data_interval_ms
        self._buffer: deque[ImuSample] = deque()
        self._attached = False
        self._last_sample_at: float | None = None
        self.latest: ImuSample | None = None
        self.received = 0  # samples since construction
        self.dropped = 0  # samples lost because nobody drained them in time

    @property
    def attached(self) -> bool:
        return self._attached

    @property
    def silence_timeout_s(self) -> float:
        """No sample for this long while attached is a fault."""
        return max(0.5, 25.0 * self.data_interval_ms / 1000.0)

    def drain(self) -> list[ImuSample]:
        """Every sample collected since the last call, oldest first."""
        out = list(self._buffer)
        self._buffer.clear()
        return out

    def zero_gyro(self) -> None:
        """Ask the board to re-measure its gyro bias (keep the robot still for ~2 s)."""
        if not self.ready():
            raise DeviceError(self.name, "cannot zero the gyro: the IMU is not attached")
        log.info("%s: zeroing the gyro; keep the robot still for 2 s", self.name)
        self._zero_gyro()

    def tick(self, now: float, dt: float) -> None:
        super().tick(now, dt)
        last = self._last_sample_at
        if (last is not None and self.fault is None and self.is_open and self._attached
                and now - last > self.silence_timeout_s):
            self._set_fault(DeviceError(
                self.name, f"attached but no sample for {now - last:.2f} s "
                f"(data interval {self.data_interval_ms} ms)"))

    # -- for drivers ------------------------------------------------------------------------
    def _accept(self, sample: ImuSample, now: float) -> None:
        """A driver hands over one sample (on the scheduler's thread)."""
        if len(self._buffer) >= self.MAX_BUFFER:
            self._buffer.popleft()
            self.dropped += 1
        self._buffer.append(sample)
        self.latest = sample
        self.received += 1
        self._last_sample_at = now
        if self.fault is not None and self._attached:
            self._clear_fault()

    def _accept_all(self, samples: list[ImuSample], now: float) -> None:
        """A driver hands over the samples of a tick, oldest first (as `_accept` on each)."""
        buffer = self._buffer
        room = self.MAX_BUFFER
        for sample in samples:
            if len(buffer) >= room:
                buffer.popleft()
                self.dropped += 1
            buffer.append(sample)
        self.latest = samples[-1]
        self.received += len(samples)
        self._last_sample_at = now
        if self.fault is not None and self._attached:
            self._clear_fault()

    def _attach(self, now: float) -> None:
        self._attached = True
        self._last_sample_at = now  # the silence clock starts at the attach
        self._clear_fault()

    def _detach(self, why: str) -> None:
        self._attached = False
        self._last_sample_at = None
        self._set_fault(DeviceError(self.name, why))

    @abstractmethod
    def _zero_gyro(self) -> None: ...


# -- pan/tilt ----------------------------------------------------------------------------------
class Servo(ABC):
    """One RC servo axis of the gimbal, in the gimbal's degrees.

    Commands are checked and recorded here; the driver hands them to the controller from its
    tick (or at once, for the emulator). `position_deg` is what the controller reports (it
    has no feedback from the servo: it is the pulse it is sending, turned into degrees), None
    until known and while disengaged.
    """

    def __init__(self, gimbal_name: str, config: ServoConfig) -> None:
        self.config = config
        self.label = f"{gimbal_name}.{config.name}"
        self.target_deg: float | None = None
        self.velocity_limit_dps = config.velocity_dps
        self.acceleration_dps2 = config.acceleration_dps2
        self.engaged = False  # as commanded
        self.position_deg: float | None = None
        self.reached = False  # the current target has been reached
        self.reached_count = 0  # target-reached events so far
        self.attached = False

    @property
    def limits(self) -> tuple[float, float]:
        return (self.config.min_deg, self.config.max_deg)

    def check_target(self, deg: float) -> float:
        """`deg` as a float if this axis can go there; ValueError naming the axis if not."""
        deg = _finite(deg, "target", self.label)
        lo, hi = self.limits
        if not lo <= deg <= hi:
            raise ValueError(f"{self.label}: target {deg:g} deg is outside {lo:g}..{hi:g}")
        return deg

    def clamp(self, deg: float) -> float:
        """`deg` moved inside this axis's limits (for callers that prefer to saturate)."""
        cfg = self.config  # `limits`, read without making the pair
        return min(cfg.max_deg, max(cfg.min_deg, _finite(deg, "angle", self.label)))

    def set_target(self, deg: float) -> None:
        deg = self.check_target(deg)
        self.target_deg = deg
        self.reached = False
        self._apply_target(deg)

    def set_velocity_limit(self, dps: float) -> None:
        dps = _finite(dps, "velocity limit", self.label)
        if not 0.0 < dps <= MAX_VELOCITY_DPS:
            raise ValueError(f"{self.label}: velocity limit {dps:g} deg/s is outside "
                             f"0..{MAX_VELOCITY_DPS:g}")
        self.velocity_limit_dps = dps
        self._apply_velocity_limit(dps)

    def set_acceleration(self, dps2: float) -> None:
        dps2 = _finite(dps2, "acceleration", self.label)
        if not 0.0 < dps2 <= MAX_ACCELERATION_DPS2:
            raise ValueError(f"{self.label}: acceleration {dps2:g} deg/s^2 is outside "
                             f"0..{MAX_ACCELERATION_DPS2:g}")
        self.acceleration_dps2 = dps2
        self._apply_acceleration(dps2)

    def set_engaged(self, on: bool) -> None:
        on = bool(on)
        if on and self.target_deg is None:
            raise ValueError(f"{self.label}: set a target before engaging (an RC servo jumps "
                             "to its target the moment it is engaged)")
        if on != self.engaged:
            log.info("%s: %s", self.label, "engaged" if on else "disengaged")
        self.engaged = on
        if not on:
            self.position_deg = None
        self._apply_engaged(on)

    # -- for drivers ------------------------------------------------------------------------
    def _report_position(self, deg: float) -> None:
        self.position_deg = deg

    def _report_reached(self, deg: float, tolerance: float = 1e-6) -> None:
        """The controller says it reached `deg`; stale news of an older target is ignored."""
        self.position_deg = deg
        if self.target_deg is not None and abs(deg - self.target_deg) <= tolerance:
            self.reached = True
            self.reached_count += 1

    @abstractmethod
    def _apply_target(self, deg: float) -> None: ...

    @abstractmethod
    def _apply_velocity_limit(self, dps: float) -> None: ...

    @abstractmethod
    def _apply_acceleration(self, dps2: float) -> None: ...

    @abstractmethod
    def _apply_engaged(self, on: bool) -> None: ...


class PanTilt(Device):
    """Two RC servos on one controller board carrying the LIDAR (thesis figs. 5.28-5.32)."""

    def __init__(self, config: GimbalConfig, name: str = "gimbal") -> None:
        super().__init__(name, config.attach_timeout_s)
        self.config = config
        self.pan = self._make_servo(config.pan)
        self.tilt = self._make_servo(config.tilt)

    @property
    def servos(self) -> tuple[Servo, Servo]:
        return (self.pan, self.tilt)

    @property
    def attached(self) -> bool:
        return self.pan.attached and self.tilt.attached

    @property
    def reached(self) -> bool:
        """Both axes have reached their current targets."""
        return self.pan.reached and self.tilt.reached

    def angles(self) -> tuple[float | None, float | None]:
        """(pan, tilt) in degrees as the controller reports them."""
        return (self.pan.position_deg, self.tilt.position_deg)

    def point(self, pan_deg: float, tilt_deg: float) -> None:
        """Aim both axes; checks both first, so a bad angle changes nothing."""
        pan = self.pan.check_target(pan_deg)
        tilt = self.tilt.check_target(tilt_deg)
        self.pan.set_target(pan)
        self.tilt.set_target(tilt)

    def engage(self, on: bool = True) -> None:
        """Engage (or relax) both servos; checks both first."""
        if on:
            for s in self.servos:
                if s.target_deg is None:
                    raise ValueError(f"{s.label}: set a target before engaging (point() "
                                     "both axes first)")
        for s in self.servos:
            s.set_engaged(on)

    def _not_attached_error(self) -> DeviceError:
        missing = [s for s in self.servos if not s.attached]
        names = " and ".join(f"{s.config.name} (channel {s.config.channel})" for s in missing)
        return DeviceError(self.name, f"servo controller not attached within "
                           f"{self.attach_timeout_s:g} s: {names} - check the USB cable and "
                           "the serial number", missing[0].label if missing else "")

    @abstractmethod
    def _make_servo(self, config: ServoConfig) -> Servo: ...
