"""Scan collector: every LIDAR scan as a `ScanRecord`, with where the LIDAR pointed and how
the chassis stood when it was taken.

It listens to the LIDAR driver and, for each scan, works out when the scan was taken on the
host's clock, the servo angles the gimbal's controller reported then (pan and tilt, from a
short history sampled every tick), the LIDAR's pose on the chassis from those angles
(`ramp.autonomy.mount.lidar_pose`, the config's mount and pivot), and the AHRS attitude then
(`Ahrs.attitude_at`). Consumers (the localizer, the re-leveller, the 3D sweep, plots) read
`latest`, `records`, or register a listener.

**When a scan was taken.** The sensor stamps each scan with its own millisecond clock at step
0; the host knows when the last byte arrived. The smallest difference seen so far between the
two is the sensor-to-host offset plus the least possible delay (the scan's own 18.75 ms of
measuring, then the wire), so `sensor_time + offset - (AMAX - AFRT) / ARES * period` is the
moment the beam straight ahead was measured, on the host clock, within a few milliseconds and
free of the network's jitter. The minimum is let creep by `CLOCK_DRIFT` so drifting clocks
cannot hold it; a sensor clock that runs backwards (a reboot, RS) starts the estimate afresh.
"""

from __future__ import annotations

import bisect
import logging
from collections import deque
from collections.abc import Callable

from ramp.autonomy.hal.interfaces import PanTilt
from ramp.autonomy.hal.lidar import Lidar, Scan
from ramp.autonomy.mount import Mat3, Mount, Vec3, lidar_pose
from ramp.autonomy.perception.ahrs import Ahrs
from ramp.autonomy.perception.records import ScanRecord

log = logging.getLogger("ramp.autonomy.scans")

RecordListener = Callable[[ScanRecord], None]

#: Sensor clock against host clock, s/s: quartz on both sides (ASSUMPTION: 100 ppm at most).
CLOCK_DRIFT = 1e-4


class ScanCollector:
    """Turns the LIDAR's scans into `ScanRecord`s; `tick` samples the servo angles."""

    def __init__(self, lidar: Lidar, pan_tilt: PanTilt, ahrs: Ahrs, lidar_mount: Mount,
                 pivot: Vec3, *, keep: int = 400, history_s: float = 2.0) -> None:
        self.lidar = lidar
        self.pan_tilt = pan_tilt
        self.ahrs = ahrs
        self.lidar_mount = lidar_mount
        self.pivot = pivot
        self.history_s = history_s
        self.records: deque[ScanRecord] = deque(maxlen=keep)
        self.latest: ScanRecord | None = None
        self.skipped = 0  # scans dropped: the gimbal's angles were unknown (disengaged)
        self._listeners: list[RecordListener] = []
        self._times: deque[float] = deque()
        self._angles: deque[tuple[float, float]] = deque()
        self._offset: float | None = None  # host time - sensor time, smallest seen
        self._last_sensor_time = float("-inf")
        self._pose_for: tuple[tuple[float, float], tuple[Vec3, Mat3]] | None = None
        lidar.add_listener(self._on_scan)

    def add_listener(self, fn: RecordListener) -> None:
        self._listeners.append(fn)

    def remove_listener(self, fn: RecordListener) -> None:
        if fn in self._listeners:
            self._listeners.remove(fn)

    def close(self) -> None:
        self.lidar.remove_listener(self._on_scan)

    # -- the task ------------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        """Sample the gimbal's reported angles (for scans that arrive later)."""
        pan, tilt = self.pan_tilt.angles()
        times, angles = self._times, self._angles
        if pan is None or tilt is None:
            times.clear()
            angles.clear()
            return
        times.append(now)
        angles.append((pan, tilt))
        history_s = self.history_s
        while len(times) > 2 and now - times[1] > history_s:
            times.popleft()
            angles.popleft()

    def angles_at(self, t: float) -> tuple[float, float] | None:
        """(pan, tilt) in degrees reported at clock time `t`, interpolated; None if unknown."""
        times, angles = self._times, self._angles
        if not times:
            pan, tilt = self.pan_tilt.angles()
            return None if pan is None or tilt is None else (pan, tilt)
        if t <= times[0]:
            return angles[0]
        if t >= times[-1]:
            now = self.pan_tilt.angles()
            return angles[-1] if now[0] is None or now[1] is None else (now[0], now[1])
        i = bisect.bisect_right(times, t)
        t0, t1 = times[i - 1], times[i]
        a, b = angles[i - 1], angles[i]
        f = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))

    def scan_time(self, scan: Scan) -> float:
        """The host clock time at which the beam straight ahead was measured."""
        if scan.sensor_time < self._last_sensor_time:
            self._offset = None  # the sensor's clock restarted
        elapsed = scan.sensor_time - self._last_sensor_time
        self._last_sensor_time = scan.sensor_time
        offset = scan.received_at - scan.sensor_time
        if self._offset is None:
            self._offset = offset
        else:
            # The two clocks drift apart slowly: let the least delay creep up by CLOCK_DRIFT
            # so an old minimum cannot hold the estimate early for ever.
            self._offset = min(offset, self._offset + CLOCK_DRIFT * elapsed)
        g = scan.geometry
        # Step s is measured s / ARES of a turn after step 0; the data is complete once step
        # AMAX is, so the least delay is (AMAX + 1) / ARES of a turn.
        ready = (g.amax + 1) / g.ares * g.scan_period_s
        front = g.afrt / g.ares * g.scan_period_s
        return scan.sensor_time + self._offset - ready + front

    @staticmethod
    def lead_s(scan: Scan) -> float:
        """How long before its beam ahead a scan's first beam was measured, s."""
        g = scan.geometry
        return (g.afrt - scan.first_step) / g.ares * g.scan_period_s

    def _on_scan(self, scan: Scan) -> None:
        t = self.scan_time(scan)
        angles = self.angles_at(t)
        if angles is None:
            self.skipped += 1
            return
        pan, tilt = angles
        if self._pose_for is None or self._pose_for[0] != angles:  # the gimbal moved
            self._pose_for = (angles, lidar_pose(self.lidar_mount, self.pivot, pan, tilt))
        position, rotation = self._pose_for[1]
        roll, pitch, yaw = self.ahrs.attitude_at(t)
        record = ScanRecord(t=t, ranges=scan.ranges, angles=scan.angles,
                            lidar_position=position, lidar_rotation=rotation, roll=roll,
                            pitch=pitch, yaw=yaw if self.ahrs.yaw_known else None,
                            pan_deg=pan, tilt_deg=tilt, started=t - self.lead_s(scan))
        self.records.append(record)
        self.latest = record
        for fn in list(self._listeners):
            try:
                fn(record)
            except Exception:
                log.exception("scan record listener raised; the collector goes on")

    def since(self, t: float) -> list[ScanRecord]:
        """The records kept that were taken at or after clock time `t`."""
        return [r for r in self.records if r.t >= t]
