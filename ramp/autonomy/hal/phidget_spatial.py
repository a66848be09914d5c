"""`phidget` IMU driver: a PhidgetSpatial 3/3/3 through Phidget22's `Spatial` channel.

The board sends a SpatialData event every data interval: acceleration (g), angular rate
(deg/s), magnetic field (gauss, PUNK_DBL when it has none this time) and its own timestamp in
milliseconds. The handler copies them onto a queue; `tick` turns them into `ImuSample`s on the
scheduler's thread. After a USB re-attach the board restarts its timestamp from 0 and forgets
its data interval (ros-drivers/phidgets_drivers 1.0.5 changelog), so the interval is set again
on every attach and the timestamp is re-anchored whenever it runs backwards.

Sample times: `t` is the board's timestamp laid onto the scheduler's clock, anchored when the
first samples after an attach are drained (the newest of them at that tick) and never later
than the tick that drains a sample, so the spacing between samples is the board's (exact) and
not the USB's (jittery).
"""

from __future__ import annotations

import logging
import math
import queue
from dataclasses import dataclass
from typing import Any

from ramp.autonomy.config import ImuConfig
from ramp.autonomy.hal.interfaces import Imu, ImuSample, Vec3
from ramp.common import phidget22 as pc
from ramp.errors import DeviceError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SpatialApi:
    """The parts of Phidget22 this driver uses (names as in Phidget22)."""

    Spatial: Any
    PhidgetException: type[BaseException]


def load_phidget22() -> SpatialApi:
    from Phidget22.Devices.Spatial import Spatial
    from Phidget22.PhidgetException import PhidgetException

    return SpatialApi(Spatial=Spatial, PhidgetException=PhidgetException)


class PhidgetImu(Imu):
    driver_name = "phidget"

    def __init__(self, config: ImuConfig, name: str = "imu", *,
                 api: SpatialApi | None = None) -> None:
        super().__init__(config, name)
        self._api = api
        self._ch: Any = None
        self._queue: queue.SimpleQueue[pc.Event] = queue.SimpleQueue()
        self._anchor: tuple[float, float] | None = None  # (clock s, board ms)
        #: The time of the last sample handed on: a re-anchored stretch never goes before it.
        self._last_t = -math.inf
        self._last_ms: float | None = None
        #: Error events seen, per Phidget22 error-event code.
        self.error_counts: dict[int, int] = {}
        self._error_code: int | None = None

    def where(self) -> str:
        serial = "any serial" if self.config.serial < 0 else f"serial {self.config.serial}"
        return f"PhidgetSpatial ({serial}, channel {self.config.channel})"

    # -- lifecycle --------------------------------------------------------------------------
    def _open(self, now: float) -> None:
        if self._api is None:
            try:
                self._api = pc.import_phidget22(load_phidget22)
            except pc.PhidgetUnavailable as exc:
                raise DeviceError(self.name, str(exc)) from exc.__cause__
        api = self._api
        # A fresh queue per open: late events from a previous handle land in the old one.
        q: queue.SimpleQueue[pc.Event] = queue.SimpleQueue()
        self._queue = q
        self._anchor = None
        self._last_ms = None
        self._attached = False
        try:
            ch = pc.construct(api.Spatial)
        except pc.PhidgetUnavailable as exc:
            raise DeviceError(self.name, str(exc)) from exc.__cause__
        try:
            pc.match(ch, self.config.serial, self.config.hub_port, self.config.channel)
            pc.common_handlers(ch, q, None)

            # Runs on libphidget22's thread: copy the numbers onto the queue, nothing else.
            def on_data(_ch: Any, acceleration: Any, angular_rate: Any, magnetic_field: Any,
                        timestamp: Any) -> None:
                q.put(("data", None, (tuple(acceleration), tuple(angular_rate),
                                      tuple(magnetic_field), timestamp)))

            ch.setOnSpatialDataHandler(on_data)
            ch.open()  # returns at once; the attach comes as an event
        except api.PhidgetException as exc:
            pc.close_quietly(ch, self.where())
            raise DeviceError(self.name, f"cannot open the {self.where()}: "
                              f"{pc.describe(exc)}") from exc
        self._ch = ch

    def _tick(self, now: float, dt: float) -> None:
        run: list[tuple[Any, ...]] = []  # consecutive samples, timed together
        for event, _which, payload in pc.drain(self._queue):
            if event == "data":
                if self._attached:
                    run.append(payload)
                continue
            self._samples(now, run)
            run = []
            if event == "attach":
                self._on_attach(now)
            elif event == "detach":
                self._detach(f"{self.where()} detached")
            elif event == "error":
                self._on_error(*payload)
        self._samples(now, run)

    def _close(self) -> None:
        ch, self._ch = self._ch, None
        self._attached = False
        pc.close_quietly(ch, self.where())

    def _zero_gyro(self) -> None:
        api = self._api
        assert api is not None and self._ch is not None
        try:
            self._ch.zeroGyro()
        except api.PhidgetException as exc:
            raise DeviceError(self.name, f"zeroGyro failed: {pc.describe(exc)}") from exc

    # -- events -----------------------------------------------------------------------------
    def _on_attach(self, now: float) -> None:
        api = self._api
        assert api is not None
        try:
            ms = pc.clamp_interval(self._ch, self.config.data_interval_ms, self.name)
            self._ch.setDataInterval(ms)
        except api.PhidgetException as exc:
            self._attached = False
            self._set_fault(DeviceError(self.name, f"cannot set the data interval of the "
                                        f"{self.where()}: {pc.describe(exc)}"))
            return
        self.data_interval_ms = ms
        self._anchor = None  # the board's timestamp restarts at every attach
        self._last_ms = None
        self._attach(now)
        log.info("%s: %s attached, a sample every %d ms", self.name, self.where(), ms)

    def _on_error(self, code: Any, description: Any) -> None:
        key = int(code)
        self.error_counts[key] = self.error_counts.get(key, 0) + 1
        if self._error_code != key:  # once per condition, not once per sample
            self._error_code = key
            log.warning("%s: %s: error event %s: %s", self.name, self.where(), key, description)

    def _samples(self, now: float, run: list[tuple[Any, ...]]) -> None:
        """Lay the board's timestamps onto the clock: a fresh anchor (after an attach, or
        when the board's time runs backwards) puts the newest sample of its stretch at
        `now`, no sample is ever later than `now`, and none is earlier than the one before."""
        start = 0
        for i in range(len(run) + 1):
            if i < len(run) and not (i > start and float(run[i][3]) < float(run[i - 1][3])):
                continue
            part = run[start:i]
            start = i
            if not part:
                continue
            first_ms, last_ms = float(part[0][3]), float(part[-1][3])
            if self._anchor is None or self._last_ms is None or first_ms < self._last_ms:
                self._anchor = (now, last_ms)
            t0, ms0 = self._anchor
            late = t0 + (last_ms - ms0) / 1000.0 - now
            if late > 0.0:  # the board's clock ran ahead of ours: never report the future
                self._anchor = (t0 - late, ms0)
            t0, ms0 = self._anchor
            for accel, gyro, mag, timestamp_ms in part:
                ms = float(timestamp_ms)
                # Pulling the anchor back (a board clock that ran ahead) must not put a sample
                # before one already handed on: sample times only ever go forward.
                t = max(t0 + (ms - ms0) / 1000.0, self._last_t)
                self._last_t = t
                self._accept(ImuSample(t=t, timestamp_ms=ms,
                                       accel_g=_vec(accel), gyro_dps=_vec(gyro),
                                       mag_gauss=_mag(mag)), now)
            self._last_ms = last_ms
            self._error_code = None


def _vec(v: tuple[float, ...]) -> Vec3:
    return (float(v[0]), float(v[1]), float(v[2]))


def _mag(v: tuple[float, ...]) -> Vec3 | None:
    if len(v) != 3 or any(not math.isfinite(x) or abs(x) >= pc.PUNK_DBL / 10 for x in v):
        return None
    return _vec(v)
