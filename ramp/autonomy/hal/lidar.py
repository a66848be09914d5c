"""The LIDAR as the autonomy's perception code sees it: scans in metres, a state, a fault.

A driver subclasses `Lidar` and implements the hooks (`_start`, `_tick`, `_stop`,
`_request_scan`, `_start_stream`, `_stop_stream`); the public methods keep the bookkeeping
(state, fault text, the newest scan, listeners) in one place. Nothing here blocks: a scan
asked for with `request_scan()` arrives later, in `latest` and through `on_scan` listeners,
and every call returns at once.

Geometry (from the sensor's PP reply): step s points at (s - AFRT) * 2π / ARES radians,
counter-clockwise seen from above, 0 straight ahead along the sensor's x axis. On a
UTM-30LX-EW that is steps 0..1080, 540 ahead, 1440 steps per turn (0.25°), so the scan
spans -135°..+135°.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from types import TracebackType

import numpy as np
import numpy.typing as npt

log = logging.getLogger("ramp.autonomy.lidar")

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: Lifecycle states every LIDAR driver reports.
STOPPED = "stopped"  # not started, or stopped
CONNECTING = "connecting"  # link being opened
CONFIGURING = "configuring"  # link up, checking the sensor and switching the laser on
READY = "ready"  # laser on, scans on demand
STREAMING = "streaming"  # scans arriving continuously
FAULT = "fault"  # the sensor reports a fault; no scans are served until it clears
DISCONNECTED = "disconnected"  # link lost or refused; retrying after a back-off
STATES = (STOPPED, CONNECTING, CONFIGURING, READY, STREAMING, FAULT, DISCONNECTED)


@dataclass(frozen=True)
class ScanGeometry:
    """How steps map to bearings and which ranges are real (the sensor's PP numbers)."""

    ares: int = 1440  # steps per full turn
    amin: int = 0  # first step
    amax: int = 1080  # last step
    afrt: int = 540  # the step straight ahead
    dmin_m: float = 0.023  # shorter readings are error codes ("no return" and friends)
    dmax_m: float = 60.0
    scan_period_s: float = 0.025

    @property
    def step_rad(self) -> float:
        return 2 * np.pi / self.ares

    def angle(self, step: float) -> float:
        """Bearing of `step` in radians, counter-clockwise from straight ahead."""
        return (step - self.afrt) * self.step_rad

    def angles(self, first: int | None = None, last: int | None = None,
               cluster: int = 1) -> FloatArray:
        """Bearing of each value of a scan of steps `first..last` grouped by `cluster`
        (the centre of each group)."""
        lo = self.amin if first is None else first
        hi = self.amax if last is None else last
        c = max(1, cluster)
        starts = np.arange(lo, hi + 1, c, dtype=np.float64)
        centres = starts + (np.minimum(starts + c - 1, hi) - starts) / 2.0
        return (centres - self.afrt) * self.step_rad


@dataclass(frozen=True, eq=False)
class Scan:
    """One scan: ranges in metres with NaN where the sensor saw nothing usable."""

    sensor_time: float  # the sensor's own clock at step 0, unwrapped, in seconds
    received_at: float  # host clock (the injected one) when the last byte arrived
    ranges: FloatArray  # metres; NaN where `valid` is False
    valid: BoolArray  # DMIN <= reading <= DMAX
    raw: IntArray  # what the sensor sent: mm, or an error code below DMIN
    geometry: ScanGeometry
    first_step: int = 0
    last_step: int = 1080
    cluster: int = 1
    seq: int = 0  # counts scans from this driver since it started
    sensor_ms: int = 0  # the raw 24-bit timestamp, as sent
    tag: str = field(default="", repr=False)

    @cached_property
    def angles(self) -> FloatArray:
        """Bearing of each element of `ranges`, radians counter-clockwise from ahead."""
        key = (self.geometry, self.first_step, self.last_step, self.cluster)
        angles = _ANGLES.get(key)
        if angles is None:  # the same for every scan of a stream: made once, copied out
            angles = self.geometry.angles(self.first_step, self.last_step, self.cluster)
            if len(_ANGLES) >= 64:
                _ANGLES.clear()
            _ANGLES[key] = angles
        return angles.copy()

    @property
    def steps(self) -> IntArray:
        """The first step of each element of `ranges`."""
        return np.arange(self.first_step, self.last_step + 1, max(1, self.cluster),
                         dtype=np.int64)

    def points(self) -> FloatArray:
        """(n, 2) x, y of the valid returns in the sensor's frame (x ahead, y left)."""
        a = self.angles[self.valid]
        r = self.ranges[self.valid]
        return np.column_stack((r * np.cos(a), r * np.sin(a)))

    def range_at(self, bearing: float) -> float:
        """The range of the element nearest `bearing` (radians), NaN when invalid."""
        i = int(np.argmin(np.abs(self.angles - bearing)))
        return float(self.ranges[i])

    @classmethod
    def from_raw(cls, raw: IntArray, geometry: ScanGeometry, *, sensor_time: float,
                 received_at: float, first_step: int | None = None,
                 last_step: int | None = None, cluster: int = 1, seq: int = 0,
                 sensor_ms: int = 0, tag: str = "") -> Scan:
        """Build a scan from the sensor's integers (mm or error codes)."""
        values = np.asarray(raw, dtype=np.int64)
        metres = values.astype(np.float64) / 1000.0
        valid = (metres >= geometry.dmin_m) & (metres <= geometry.dmax_m)
        ranges = np.where(valid, metres, np.nan)
        first = geometry.amin if first_step is None else first_step
        last = geometry.amax if last_step is None else last_step
        return cls(sensor_time, received_at, ranges, valid, values, geometry, first, last,
                   max(1, cluster), seq, sensor_ms, tag)


ScanListener = Callable[[Scan], None]

#: `ScanGeometry.angles` by (geometry, first, last, cluster): a pure function of the four,
#: asked for every scan (each gets its own copy, so nobody can change another's).
_ANGLES: dict[tuple[ScanGeometry, int, int, int], FloatArray] = {}


class Lidar(ABC):
    """A planar scanning rangefinder driven from one loop: `start`, `tick(now, dt)`, `stop`.

    Public methods validate and keep state; drivers implement the `_hooks`. `state` is one
    of `STATES`; `fault` says in words what is wrong ("" when nothing is).
    """

    def __init__(self, name: str = "lidar") -> None:
        self.name = name
        self._state = STOPPED
        self._fault = ""
        self._latest: Scan | None = None
        self._listeners: list[ScanListener] = []
        self._seq = 0
        self.streaming_wanted = False  # what the user asked for; survives reconnects

    # -- what perception reads ----------------------------------------------------------------
    @property
    def state(self) -> str:
        return self._state

    @property
    def fault(self) -> str:
        return self._fault

    @property
    def latest(self) -> Scan | None:
        """The newest good scan (never one the sensor flagged as faulty)."""
        return self._latest

    @property
    def scans_received(self) -> int:
        return self._seq

    def add_listener(self, fn: ScanListener) -> None:
        """Call `fn(scan)` for every scan as it arrives (inside the loop; keep it short)."""
        self._listeners.append(fn)

    def remove_listener(self, fn: ScanListener) -> None:
        if fn in self._listeners:
            self._listeners.remove(fn)

    # -- lifecycle ------------------------------------------------------------------------------
    def start(self) -> None:
        """Begin connecting; returns at once."""
        if self._state != STOPPED:
            return
        self._set_state(CONNECTING)
        self._start()

    def tick(self, now: float, dt: float) -> None:
        """One iteration of the driver's work (the scheduler calls it)."""
        if self._state != STOPPED:
            self._tick(now, dt)

    def stop(self) -> None:
        """Stop streaming, switch the laser off where possible, close. Idempotent."""
        if self._state == STOPPED:
            return
        try:
            self._stop()
        finally:
            self._set_state(STOPPED)

    close = stop

    def __enter__(self) -> Lidar:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()

    # -- scans ----------------------------------------------------------------------------------
    def request_scan(self) -> bool:
        """Ask for one scan (GD). True when one is on its way; False when the sensor cannot
        serve one now (see `state` and `fault`), or a stream is running (use `latest`)."""
        if self._state != READY:
            return False
        return self._request_scan()

    def start_stream(self) -> None:
        """Scans continuously (MD) from now on, across reconnects, until `stop_stream`."""
        self.streaming_wanted = True
        if self._state == READY:
            self._start_stream()

    def stop_stream(self) -> None:
        """Back to scans on demand (QT, then the laser on again)."""
        self.streaming_wanted = False
        if self._state == STREAMING:
            self._stop_stream()

    # -- for drivers ----------------------------------------------------------------------------
    def _set_state(self, state: str, fault: str | None = None) -> None:
        if state not in STATES:
            raise ValueError(f"unknown LIDAR state {state!r}")
        if fault is not None and fault != self._fault:
            if fault:
                log.warning("%s", fault)
            elif self._fault:
                log.info("%s: recovered (%s)", self.name, state)
            self._fault = fault
        if state != self._state:
            log.debug("%s: %s -> %s", self.name, self._state, state)
            self._state = state

    def _publish(self, scan: Scan) -> None:
        self._latest = scan
        for fn in list(self._listeners):
            try:
                fn(scan)
            except Exception:
                log.exception("%s: scan listener raised; the driver goes on", self.name)

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    @abstractmethod
    def _start(self) -> None: ...

    @abstractmethod
    def _tick(self, now: float, dt: float) -> None: ...

    @abstractmethod
    def _stop(self) -> None: ...

    @abstractmethod
    def _request_scan(self) -> bool: ...

    @abstractmethod
    def _start_stream(self) -> None: ...

    @abstractmethod
    def _stop_stream(self) -> None: ...
