"""A Hokuyo UTM-30LX-EW speaking SCIP 2.0 on loopback TCP, for tests and simulation.

It has its own encoder, written like the sensor's firmware, and never imports `ramp`: it is
an independent check of the driver, which it meets only through bytes on a TCP socket.

Two layers:
- `HokuyoSensor`: the sensor as a sans-IO state machine (`feed(now, bytes)`, `service(now)`,
  `take_output()`), with the states booting / idle / single scan (laser on) / multi scan
  (MD/MS) / time adjust (TM) / error, the real status codes, the remaining-scan counter of
  MD/MS, the 24-bit millisecond timestamp, reboot (two RB within 1 s) and laser on/off.
- `HokuyoEmulator`: that sensor behind a listening TCP socket, serviced from a loop: call
  `service(now)` every tick (scans are timed from the clock given to it), or `attach(loop)`
  so an event loop with `add_reader` calls it when bytes arrive. No threads.

Behaviour modelled (Hokuyo SCIP 2.0 spec C-42-03320B; seqsense `urg_stamped` urg_sim):
- The motor turns at 2400 rpm: scan k starts at `epoch + k * 25 ms` and its data is ready
  once step AMAX has been measured (18.8 ms later). The timestamp is the counter at step 0.
- Commands are served one at a time in arrival order; GD/GS waits for the next complete
  scan (so replies stay in order); MD/MS is acknowledged at once and then sends every
  (interval + 1)-th scan, `scans` of them (00 = until QT), with the scans still to come in
  the echo; when the count runs out the laser goes off.
- BM: 00, 02 if already on, 01 in error. QT: laser off, stops MD, 00 (0L in error).
  GD with the laser off: 10. TM0/1/2 with the spec's statuses (TM1 answers outside adjust
  mode too, as real sensors do). RS resets the timer. RB: 01, then 00 on a second RB within
  1 s, the connection closes and the sensor boots for `boot_time`.
- Errors: an unknown command 0E, too short 0C, junk after the parameters 0D, a tag over 16
  letters 0G; malformed scan parameters 01-07 as the spec lists them.
- `inject_error(code)` (50-98) puts the sensor in its error state: a running MD stream gets
  one reply with that status and stops; GD/MD answer it; BM answers 01; QT/RS/TM 0L; II shows
  it. `clear_error()` or a reboot ends it. `laser_fault = True` makes only BM fail (01);
  `muted = True` makes the sensor hang with the link up; `corrupt_next = n` spoils the sums
  of the next n scans; `HokuyoEmulator.drop_connection()` cuts the link.
- ASSUMPTION: a new TCP connection replaces the previous one (the real sensor serves one
  client); a closed connection stops the laser, as urg_sim does.
- ASSUMPTION: 2-character data (GS/MS) is clipped to 4095 mm.

Range source contract: `range_source(t) -> array of AMAX + 1 (1081) integers`, the
distance in mm seen by steps 0..1080 at clock time `t` (the scan's step-0 time); values below
DMIN (23) are the sensor's error codes (1 = no object in range). Step s points at
(s - 540) * 0.25 degrees, counter-clockwise from the sensor's front.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import select
import socket
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

RangeSource = Callable[[float], npt.ArrayLike]

BOOTING = "booting"
IDLE = "idle"
SINGLE_SCAN = "single_scan"  # laser on, GD/GS served
MULTI_SCAN = "multi_scan"  # MD/MS stream running
TIME_ADJUST = "time_adjust"
ERROR = "error"

NO_OBJECT = 1  # UTM-30LX error code: no object in range
TIMESTAMP_MASK = 0xFFFFFF
MAX_CATCH_UP = 40  # scans sent at most per service() after a long pause (1 s of data)
MAX_OUTPUT = 1 << 20  # bytes queued for a client that does not read


class Clock(Protocol):
    def now(self) -> float: ...


# -- the sensor's own encoder (independent of ramp.autonomy.hal.scip) --------------------------
def _sum(content: bytes) -> bytes:
    return bytes(((sum(content) & 0x3F) + 0x30,))


def _line(content: bytes) -> bytes:
    return content + _sum(content) + b"\n"


def _encode_chars(values: npt.NDArray[np.int64], width: int) -> npt.NDArray[np.uint8]:
    v = values.astype(np.int32)
    out = np.empty((len(v), width), dtype=np.uint8)
    for i in range(width):
        out[:, i] = (v >> (6 * (width - 1 - i))) & 0x3F
    out += 0x30
    return out.ravel()


def _encode_one(value: int, width: int) -> bytes:
    return bytes(((value >> (6 * (width - 1 - i))) & 0x3F) + 0x30 for i in range(width))


def _data_block(chars: npt.NDArray[np.uint8]) -> bytes:
    """Scan data cut every 64 characters, each line with its sum and LF (all lines at once)."""
    full, rest = divmod(len(chars), 64)
    out = b""
    if full:
        grid = chars[:full * 64].reshape(full, 64)
        block = np.empty((full, 66), dtype=np.uint8)
        block[:, :64] = grid
        block[:, 64] = (grid.sum(axis=1, dtype=np.int64) & 0x3F) + 0x30
        block[:, 65] = 0x0A
        out = block.tobytes()
    if rest:
        out += _line(chars[full * 64:].tobytes())
    return out


def _reply(echo: str, status: str, body: bytes = b"") -> bytes:
    return echo.encode("ascii") + b"\n" + _line(status.encode("ascii")) + body + b"\n"


# -- a default world: a plain room, so the emulator runs on its own ----------------------------
def synthetic_room(length: float = 6.0, width: float = 4.0, x: float = 2.0, y: float = 1.5,
                   yaw: float = 0.0, pillars: Sequence[tuple[float, float, float]] = (
                       (4.0, 2.6, 0.15), (3.2, 0.6, 0.10)),
                   steps: int = 1081, front: int = 540, ares: int = 1440,
                   max_range: float = 30.0) -> RangeSource:
    """A range source for a sensor at (x, y, yaw) in a `length` × `width` m room with round
    pillars (x, y, radius); ranges in mm, NO_OBJECT beyond `max_range`. Fixed in time."""
    a = yaw + (np.arange(steps) - front) * (2 * np.pi / ares)
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c > 1e-12, (length - x) / c, np.where(c < -1e-12, -x / c, np.inf))
        ty = np.where(s > 1e-12, (width - y) / s, np.where(s < -1e-12, -y / s, np.inf))
    r = np.minimum(tx, ty)
    for px, py, pr in pillars:
        dx, dy = px - x, py - y
        along = dx * c + dy * s
        miss2 = dx * dx + dy * dy - along * along
        hit = (along > 0) & (miss2 <= pr * pr)
        near = along - np.sqrt(np.maximum(pr * pr - miss2, 0.0))
        r = np.where(hit & (near < r), near, r)
    mm = np.where(r <= max_range, np.round(r * 1000.0), NO_OBJECT).astype(np.int64)
    mm.setflags(write=False)

    def source(t: float) -> npt.NDArray[np.int64]:
        return mm

    return source


# -- the sensor ----------------------------------------------------------------------------------
@dataclass
class _Stream:
    code: str  # MD or MS
    head: str  # the first 13 characters of the command (code, steps, cluster, interval)
    first: int
    last: int
    cluster: int
    interval: int
    scans: int  # 0 = until QT
    tag: str
    after: float  # only scans starting at or after this time
    sent: int = 0
    counted: int = 0  # scans seen since the last one sent (for the interval)


@dataclass
class _Single:
    code: str  # GD or GS
    echo: str
    first: int
    last: int
    cluster: int
    after: float


@dataclass
class SensorModel:
    """What PP and VV report, and how fast the sensor turns."""

    model: str = "UTM-30LX-EW"
    dmin: int = 23
    dmax: int = 60000
    ares: int = 1440
    amin: int = 0
    amax: int = 1080
    afrt: int = 540
    scan_rpm: int = 2400
    vendor: str = "Hokuyo Automatic Co.,Ltd."
    firmware: str = "1.0.9(17/Mar./2015)"
    protocol: str = "SCIP 2.0"
    serial: str = "H1410000"

    @property
    def period(self) -> float:
        return 60.0 / self.scan_rpm


@dataclass
class Counters:
    commands: int = 0
    replies: int = 0
    scans_sent: int = 0
    scans_skipped: int = 0  # due while nobody could take them (catch-up cap)
    unknown: int = 0
    corrupted: int = 0
    reboots: int = 0
    connections: int = 0


class HokuyoSensor:
    """The UTM-30LX-EW's SCIP side: bytes in with `feed`, bytes out with `take_output`."""

    def __init__(self, range_source: RangeSource | None = None, *, now: float = 0.0,
                 model: SensorModel | None = None, boot_time: float = 1.0,
                 timestamp_offset_ms: int = 0, semicolon_in_sum: bool = False,
                 booted: bool = True) -> None:
        self.model = model or SensorModel()
        self.range_source = range_source or synthetic_room(steps=self.model.amax + 1,
                                                           front=self.model.afrt,
                                                           ares=self.model.ares)
        self.boot_time = boot_time
        self.timestamp_offset_ms = timestamp_offset_ms
        self.semicolon_in_sum = semicolon_in_sum
        self.state = IDLE
        self.error_code = 0
        self.counters = Counters()
        #: Every command line received, in order (what the driver put on the wire).
        self.received: list[str] = []
        self.muted = False  # no replies, no scans: a sensor that hangs with the link up
        self.laser_fault = False  # the laser will not switch on: BM answers 01
        self.corrupt_next = 0  # spoil the sum of the next N scan replies
        self.hangup = False  # set after RB: the server closes the connection
        self._out = bytearray()
        self._inbox: deque[tuple[float, str]] = deque()
        self._partial = b""
        self._single: _Single | None = None
        self._stream: _Stream | None = None
        self._laser_since = math.inf
        self._rb_armed_at = -math.inf
        self._boot_done = now
        self._epoch = now
        self._k = 0
        self._t = now
        if not booted:
            self._reboot(now)

    # -- time ---------------------------------------------------------------------------------
    @property
    def period(self) -> float:
        return self.model.period

    def timestamp(self, t: float) -> int:
        """The 24-bit ms counter at clock time `t` (reset by RS and reboot)."""
        ms = math.floor((t - self._epoch) * 1000.0 + 1e-6) + self.timestamp_offset_ms
        return ms & TIMESTAMP_MASK

    def _scan_start(self, k: int) -> float:
        return self._epoch + k * (60.0 / self.model.scan_rpm)  # `period` written out

    def _scan_ready(self, k: int) -> float:
        # `_scan_start(k) + period * fraction`, written out (`service` asks every tick).
        m = self.model
        period = 60.0 / m.scan_rpm
        return self._epoch + k * period + period * ((m.amax + 1) / m.ares)

    @property
    def laser_on(self) -> bool:
        return self.state in (SINGLE_SCAN, MULTI_SCAN)

    # -- input ----------------------------------------------------------------------------------
    def feed(self, now: float, data: bytes) -> None:
        """Bytes from the host at `now`; commands end in LF or CR (CR LF counts once)."""
        buf = self._partial + data
        lines = buf.replace(b"\r\n", b"\n").replace(b"\r", b"\n").split(b"\n")
        self._partial = lines.pop()
        for raw in lines:
            if self.muted or not raw:
                continue
            text = raw.decode("ascii", "replace")
            self.received.append(text)
            self._inbox.append((now, text))
        self.service(now)

    def take_output(self) -> bytes:
        out = bytes(self._out)
        self._out.clear()
        return out

    def disconnected(self, now: float) -> None:
        """The host went away: forget its queue, stop measuring (urg_sim does the same)."""
        self._inbox.clear()
        self._partial = b""
        self._single = None
        self._stream = None
        self._out.clear()
        if self.state in (SINGLE_SCAN, MULTI_SCAN):
            self._laser(False, now)
            self.state = IDLE

    # -- faults for tests -------------------------------------------------------------------------
    def inject_error(self, code: int = 52, now: float | None = None) -> None:
        """A hardware fault (50-98): the sensor answers with it until cleared or rebooted."""
        if not 50 <= code <= 98:
            raise ValueError(f"hardware error codes are 50-98, not {code}")
        status = f"{code:02d}"
        if self._stream is not None:
            s = self._stream
            remaining = 0 if s.scans == 0 else max(0, s.scans - s.sent)
            self._emit(_reply(self._stream_echo(s, remaining), status))
            self._stream = None
        if self._single is not None:
            self._emit(_reply(self._single.echo, status))
            self._single = None
        self._laser(False, self._t if now is None else now)
        self.state = ERROR
        self.error_code = code

    def clear_error(self) -> None:
        if self.state == ERROR:
            self.state = IDLE
            self.error_code = 0

    # -- the loop ---------------------------------------------------------------------------------
    def service(self, now: float) -> None:
        """Run every event due by `now` in time order: commands, scans, the end of a boot."""
        now = max(now, self._t)
        sent_here = 0
        while True:
            if self.state == BOOTING:
                if now < self._boot_done:
                    self._t = now
                    return
                self._t = self._boot_done
                self.state = IDLE
                continue
            ready = self._scan_ready(self._k)
            head_t = self._inbox[0][0] if self._inbox and self._single is None else math.inf
            if head_t <= now and head_t <= ready:
                t, line = self._inbox.popleft()
                self._t = max(self._t, t)
                self._command(line, self._t)
            elif ready <= now:
                if not self.laser_on:  # nothing is measured: skip to the next event at once
                    horizon = min(head_t, now)
                    lead = self._scan_ready(0) - self._epoch
                    k = math.ceil((horizon - self._epoch - lead) / self.period - 1e-9)
                    self._k = max(self._k + 1, k)
                    continue
                self._t = max(self._t, ready)
                if sent_here >= MAX_CATCH_UP:  # a long pause: jump to the present
                    behind = int((now - ready) // self.period)
                    self.counters.scans_skipped += behind
                    self._k += behind + 1
                    continue
                sent_here += self._scan(self._k)
                self._k += 1
            else:
                self._t = now
                return

    def _scan(self, k: int) -> int:
        """Scan k is complete: serve a waiting GD and the stream. Returns replies sent."""
        if not self.laser_on:
            return 0
        start = self._scan_start(k)
        sent = 0
        ranges: npt.NDArray[np.int64] | None = None
        single = self._single
        if single is not None and start >= single.after:
            ranges = self._ranges(start)
            self._emit_scan(single.echo, "00", start, ranges, single.code, single.first,
                            single.last, single.cluster)
            self._single = None
            sent += 1
        stream = self._stream
        if stream is not None and start >= stream.after:
            stream.counted += 1
            if stream.counted > stream.interval:
                stream.counted = 0
                stream.sent += 1
                remaining = 0 if stream.scans == 0 else stream.scans - stream.sent
                if ranges is None:
                    ranges = self._ranges(start)
                self._emit_scan(self._stream_echo(stream, remaining), "99", start, ranges,
                                stream.code, stream.first, stream.last, stream.cluster)
                sent += 1
                if stream.scans and stream.sent >= stream.scans:
                    self._stream = None
                    self._laser(False, start)
                    self.state = IDLE
                    if self._single is not None:  # its scan will never come now
                        self._emit(_reply(self._single.echo, "10"))
                        self._single = None
        return sent

    def _ranges(self, t: float) -> npt.NDArray[np.int64]:
        values = np.asarray(self.range_source(t))
        n = self.model.amax + 1
        if values.shape != (n,):
            raise ValueError(f"range source returned shape {values.shape}, expected ({n},): "
                             f"one range in mm per step 0..{self.model.amax}")
        return np.clip(np.rint(values), 0, (1 << 18) - 1).astype(np.int64)

    def _emit_scan(self, echo: str, status: str, start: float, ranges: npt.NDArray[np.int64],
                   code: str, first: int, last: int, cluster: int) -> None:
        data = ranges[first:last + 1]
        if cluster > 1:
            data = self._cluster(data, cluster)
        width = 3 if code[1] == "D" else 2
        if width == 2:
            data = np.minimum(data, 4095)
        stamp = _line(_encode_one(self.timestamp(start), 4))
        body = _data_block(_encode_chars(data, width))
        if self.corrupt_next > 0:  # spoil the last line's sum
            self.corrupt_next -= 1
            self.counters.corrupted += 1
            spoiled = (body[-2] - 0x30 + 1) % 64 + 0x30
            body = body[:-2] + bytes((spoiled,)) + b"\n"
        self._emit(_reply(echo, status, stamp + body))
        self.counters.scans_sent += 1

    def _cluster(self, data: npt.NDArray[np.int64], cluster: int) -> npt.NDArray[np.int64]:
        """Each group of `cluster` steps gives its smallest real range (an error code only
        when every step in it is one)."""
        pad = (-len(data)) % cluster
        groups = np.pad(data, (0, pad), constant_values=-1).reshape(-1, cluster)
        real = np.where(groups >= self.model.dmin, groups, np.iinfo(np.int64).max)
        best = real.min(axis=1)
        fallback = groups[:, 0]
        return np.where(best == np.iinfo(np.int64).max, fallback, best)

    def _emit(self, data: bytes) -> None:
        if self.muted:
            return
        if len(self._out) + len(data) > MAX_OUTPUT:
            return  # the host stopped reading; a real sensor's buffer would overflow too
        self._out += data
        self.counters.replies += 1

    def _laser(self, on: bool, t: float) -> None:
        self._laser_since = t if on else math.inf

    def _stream_echo(self, s: _Stream, remaining: int) -> str:
        return s.head + f"{remaining:02d}" + (";" + s.tag if s.tag else "")

    def _reboot(self, now: float) -> None:
        self.counters.reboots += 1
        self.state = BOOTING
        self.error_code = 0
        self._single = None
        self._stream = None
        self._inbox.clear()
        self._laser(False, now)
        self._boot_done = now + self.boot_time
        self._epoch = now
        self._k = max(0, math.ceil((now - self._epoch) / self.period))

    # -- commands -----------------------------------------------------------------------------
    def _command(self, line: str, t: float) -> None:
        self.counters.commands += 1
        body, semi, tag = line.partition(";")
        code = body[:2]
        if semi and len(tag) > 16:
            self._emit(_reply(line, "0G"))
            return
        handler = {"VV": self._vv, "PP": self._pp, "II": self._ii, "BM": self._bm,
                   "QT": self._qt, "RS": self._rs, "RB": self._rb, "TM": self._tm,
                   "GD": self._gd, "GS": self._gd, "MD": self._md, "MS": self._md}.get(code)
        if handler is None:
            self.counters.unknown += 1
            self._emit(_reply(line, "0E"))
            return
        handler(line, body, t)

    def _length_ok(self, line: str, body: str, size: int) -> bool:
        if len(body) < size:
            self._emit(_reply(line, "0C"))
            return False
        if len(body) > size:
            self._emit(_reply(line, "0D"))
            return False
        return True

    def _key_values(self, line: str, pairs: list[tuple[str, str]]) -> None:
        out = []
        for key, value in pairs:
            content = f"{key}:{value}".encode("ascii")
            summed = content + b";" if self.semicolon_in_sum else content
            out.append(content + b";" + _sum(summed) + b"\n")
        self._emit(_reply(line, "00", b"".join(out)))

    def _vv(self, line: str, body: str, t: float) -> None:
        if self._length_ok(line, body, 2):
            m = self.model
            self._key_values(line, [("VEND", m.vendor), ("PROD", f"SOKUIKI Sensor {m.model}"),
                                    ("FIRM", m.firmware), ("PROT", m.protocol),
                                    ("SERI", m.serial)])

    def _pp(self, line: str, body: str, t: float) -> None:
        if self._length_ok(line, body, 2):
            m = self.model
            self._key_values(line, [("MODL", m.model), ("DMIN", str(m.dmin)),
                                    ("DMAX", str(m.dmax)), ("ARES", str(m.ares)),
                                    ("AMIN", str(m.amin)), ("AMAX", str(m.amax)),
                                    ("AFRT", str(m.afrt)), ("SCAN", str(m.scan_rpm))])

    def _ii(self, line: str, body: str, t: float) -> None:
        if not self._length_ok(line, body, 2):
            return
        mode = {BOOTING: "001 Booting", SINGLE_SCAN: "003 Single_scan",
                MULTI_SCAN: "004 Multi_scan", TIME_ADJUST: "005 Time_adjustment",
                ERROR: "006 Error"}.get(self.state, "000 Idle")
        stat = (f"Error {self.error_code:03d} hardware trouble" if self.state == ERROR
                else "Stable 000 no error.")
        stamp = _encode_one(self.timestamp(t), 4).decode("ascii")
        self._key_values(line, [("MODL", self.model.model),
                                ("LASR", "ON" if self.laser_on else "OFF"),
                                ("SCSP", f"Initial({self.model.scan_rpm}[rpm])"),
                                ("MESM", mode), ("SBPS", "Ethernet 100 [Mbps]"),
                                ("TIME", stamp), ("STAT", stat)])

    def _bm(self, line: str, body: str, t: float) -> None:
        if not self._length_ok(line, body, 2):
            return
        if self.state == ERROR or (self.laser_fault and not self.laser_on):
            self._emit(_reply(line, "01"))
        elif self.state == IDLE:
            self.state = SINGLE_SCAN
            self._laser(True, t)
            self._emit(_reply(line, "00"))
        elif self.laser_on:
            self._emit(_reply(line, "02"))
        else:
            self._emit(_reply(line, "10"))

    def _qt(self, line: str, body: str, t: float) -> None:
        if not self._length_ok(line, body, 2):
            return
        if self.state == ERROR:
            self._emit(_reply(line, "0L"))
        elif self.state == TIME_ADJUST:
            self._emit(_reply(line, "10"))
        else:
            self._stream = None
            self._laser(False, t)
            if self.state != BOOTING:
                self.state = IDLE
            self._emit(_reply(line, "00"))

    def _rs(self, line: str, body: str, t: float) -> None:
        if not self._length_ok(line, body, 2):
            return
        if self.state == ERROR:
            self._emit(_reply(line, "0L"))
            return
        self._stream = None
        self._laser(False, t)
        self.state = IDLE
        self._epoch = t  # the timer restarts; the motor's phase with it
        self._k = 0
        self._emit(_reply(line, "00"))

    def _rb(self, line: str, body: str, t: float) -> None:
        if not self._length_ok(line, body, 2):
            return
        if t - self._rb_armed_at > 1.0:
            self._rb_armed_at = t
            self._emit(_reply(line, "01"))
            return
        self._rb_armed_at = -math.inf
        self._emit(_reply(line, "00"))
        self.hangup = True
        self._reboot(t)

    def _tm(self, line: str, body: str, t: float) -> None:
        if not self._length_ok(line, body, 3):
            return
        if self.state == ERROR:
            self._emit(_reply(line, "0L"))
            return
        control = body[2]
        if control == "0":
            if self.state in (IDLE, SINGLE_SCAN):
                self._laser(False, t)
                self.state = TIME_ADJUST
                self._emit(_reply(line, "00"))
            else:
                self._emit(_reply(line, "02" if self.state == TIME_ADJUST else "10"))
        elif control == "1":
            self._emit(_reply(line, "00", _line(_encode_one(self.timestamp(t), 4))))
        elif control == "2":
            if self.state == TIME_ADJUST:
                self.state = IDLE
                self._emit(_reply(line, "00"))
            else:
                self._emit(_reply(line, "03" if self.state == IDLE else "10"))
        else:
            self._emit(_reply(line, "01"))

    def _scan_params(self, line: str, body: str, size: int) -> tuple[int, int, int] | None:
        if not self._length_ok(line, body, size):
            return None
        fields = ((body[2:6], "01"), (body[6:10], "02"), (body[10:12], "03"))
        for text, status in fields:
            if not text.isdigit():
                self._emit(_reply(line, status))
                return None
        first, last, cluster = int(body[2:6]), int(body[6:10]), int(body[10:12])
        if last > self.model.amax or first < self.model.amin:
            self._emit(_reply(line, "04"))
            return None
        if last < first:
            self._emit(_reply(line, "05"))
            return None
        return first, last, max(1, cluster)

    def _gd(self, line: str, body: str, t: float) -> None:
        params = self._scan_params(line, body, 12)
        if params is None:
            return
        if self.state == ERROR:
            self._emit(_reply(line, f"{self.error_code:02d}"))
        elif not self.laser_on:
            self._emit(_reply(line, "10"))
        else:
            self._single = _Single(body[:2], line, *params, after=max(t, self._laser_since))

    def _md(self, line: str, body: str, t: float) -> None:
        params = self._scan_params(line, body, 15)
        if params is None:
            return
        if not body[12].isdigit():
            self._emit(_reply(line, "06"))
            return
        if not body[13:15].isdigit():
            self._emit(_reply(line, "07"))
            return
        if self.state == ERROR:
            self._emit(_reply(line, f"{self.error_code:02d}"))
            return
        if self.state in (BOOTING, TIME_ADJUST):
            self._emit(_reply(line, "10"))
            return
        tag = line.partition(";")[2]
        self._stream = _Stream(body[:2], body[:13], *params, interval=int(body[12]),
                               scans=int(body[13:15]), tag=tag, after=t)
        if not self.laser_on:
            self._laser(True, t)
        self.state = MULTI_SCAN
        self._emit(_reply(line, "00"))


# -- the sensor on a TCP port ------------------------------------------------------------------
class _MonotonicClock:
    def now(self) -> float:
        return time.monotonic()  # the standalone emulator's wall clock, outside any loop


class IoLoop(Protocol):
    def add_reader(self, fd: int, callback: Callable[[], None]) -> None: ...

    def remove_reader(self, fd: int) -> None: ...


@dataclass
class _Client:
    sock: socket.socket
    out: bytearray = field(default_factory=bytearray)


class HokuyoEmulator:
    """A `HokuyoSensor` listening on TCP (loopback by default), serviced from one loop.

    `HokuyoEmulator(clock, range_source)` then, every tick, `service(now)`; `address` is
    (host, port) and `url` the `host:port` a driver connects to. `clock` is anything with
    `now()` (a `ramp.clock.VirtualClock` in simulation; wall time when None). The other
    options go to the sensor: `model` (what PP/VV report, the scan rate), `boot_time` (s, of
    a reboot), `timestamp_offset_ms` (start the 24-bit counter elsewhere, e.g. near its wrap),
    `semicolon_in_sum` (the other checksum form of VV/PP/II lines), `booted=False` (start
    booting).
    """

    def __init__(self, clock: Clock | None = None, range_source: RangeSource | None = None, *,
                 host: str = "127.0.0.1", port: int = 0, model: SensorModel | None = None,
                 boot_time: float = 1.0, timestamp_offset_ms: int = 0,
                 semicolon_in_sum: bool = False, booted: bool = True) -> None:
        self.clock: Clock = clock or _MonotonicClock()
        self.sensor = HokuyoSensor(range_source, now=self.clock.now(), model=model,
                                   boot_time=boot_time,
                                   timestamp_offset_ms=timestamp_offset_ms,
                                   semicolon_in_sum=semicolon_in_sum, booted=booted)
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind((host, port))
        self._listener.listen(4)
        self._listener.setblocking(False)
        # One poll(0) per service says whether a connection or bytes wait: an accept() or
        # recv() with nothing there costs several times more, in raising BlockingIOError.
        self._poll = select.poll()
        self._poll.register(self._listener.fileno(), select.POLLIN)
        self._client: _Client | None = None
        self._loop: IoLoop | None = None
        self.closed = False

    # -- addresses ------------------------------------------------------------------------------
    @property
    def address(self) -> tuple[str, int]:
        host, port = self._listener.getsockname()[:2]
        return str(host), int(port)

    @property
    def url(self) -> str:
        host, port = self.address
        return f"{host}:{port}"

    @property
    def connected(self) -> bool:
        return self._client is not None

    def fileno(self) -> int:
        return self._listener.fileno()

    @property
    def client_fileno(self) -> int:
        """The connected client's descriptor, -1 when none."""
        return self._client.sock.fileno() if self._client is not None else -1

    # -- servicing ------------------------------------------------------------------------------
    def service(self, now: float | None = None) -> None:
        """Accept, read, run the sensor up to `now` (the clock's time by default), write."""
        if self.closed:
            return
        t = self.clock.now() if now is None else now
        ready = self._poll.poll(0)
        if ready:  # a connection, bytes, a hang-up or an error: look as before
            self._accept(t)
            self._read(t)
        self.sensor.service(t)
        self._write(t)

    def attach(self, loop: IoLoop) -> None:
        """Let `loop` call us when a connection or bytes arrive (still call `service` from a
        periodic task: scans are due on time, not on input)."""
        self._loop = loop
        loop.add_reader(self._listener.fileno(), self.service)
        if self._client is not None:
            loop.add_reader(self._client.sock.fileno(), self.service)

    def drop_connection(self) -> None:
        """Cut the link as a pulled cable would (the host sees the connection close)."""
        self._close_client(self.clock.now())

    def inject_error(self, code: int = 52) -> None:
        self.sensor.inject_error(code, self.clock.now())
        self._write(self.clock.now())

    def clear_error(self) -> None:
        self.sensor.clear_error()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self._close_client(self.clock.now())
        if self._loop is not None:
            self._loop.remove_reader(self._listener.fileno())
        self._listener.close()

    def __enter__(self) -> HokuyoEmulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals --------------------------------------------------------------------------------
    def _accept(self, now: float) -> None:
        while True:
            try:
                sock, _ = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._close_client(now)  # the newest connection wins
            self._client = _Client(sock)
            self._poll.register(sock.fileno(), select.POLLIN)
            self.sensor.counters.connections += 1
            if self._loop is not None:
                self._loop.add_reader(sock.fileno(), self.service)

    def _read(self, now: float) -> None:
        client = self._client
        if client is None:
            return
        while True:
            try:
                data = client.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:
                self._close_client(now)
                return
            self.sensor.feed(now, data)

    def _write(self, now: float) -> None:
        sensor, client = self.sensor, self._client
        if not sensor._out and not sensor.hangup and (client is None or not client.out):
            return  # nothing to send, nothing to close (most ticks)
        out = sensor.take_output()
        if client is None:
            return
        client.out += out
        while client.out:
            try:
                n = client.sock.send(client.out)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self._close_client(now)
                return
            del client.out[:n]
        if len(client.out) > MAX_OUTPUT:
            del client.out[:len(client.out) - MAX_OUTPUT]
        if self.sensor.hangup:
            self.sensor.hangup = False
            self._close_client(now, reboot=True)

    def _close_client(self, now: float, reboot: bool = False) -> None:
        client = self._client
        if client is None:
            return
        self._client = None
        with contextlib.suppress(KeyError, ValueError):
            self._poll.unregister(client.sock.fileno())
        if self._loop is not None:
            with contextlib.suppress(Exception):
                self._loop.remove_reader(client.sock.fileno())
        with contextlib.suppress(OSError):
            client.sock.close()
        if not reboot:
            self.sensor.disconnected(now)


# -- standalone ---------------------------------------------------------------------------------
def main(argv: Sequence[str] | None = None) -> int:
    """`python -m firmware_like.hokuyo`: an emulated UTM-30LX-EW on a TCP port."""
    parser = argparse.ArgumentParser(prog="python -m firmware_like.hokuyo",
                                     description=__doc__.split("\n")[0] if __doc__ else None)
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=10940, help="TCP port (0 picks one)")
    parser.add_argument("--boot-time", type=float, default=1.0,
                        help="seconds a reboot (RB RB) takes")
    parser.add_argument("--error", type=int, metavar="CODE",
                        help="start in the error state with this hardware code (50-98)")
    args = parser.parse_args(argv)
    if args.error is not None and not 50 <= args.error <= 98:
        parser.error("--error takes a hardware error code 50-98")
    emu = HokuyoEmulator(host=args.host, port=args.port, boot_time=args.boot_time)
    if args.error is not None:
        emu.inject_error(args.error)
    print(f"hokuyo emulator ({emu.sensor.model.model}) on {emu.url}", flush=True)
    try:
        while True:
            fds = [fd for fd in (emu.fileno(), emu.client_fileno) if fd >= 0]
            select.select(fds, [], [], 0.002)
            emu.service()
    except KeyboardInterrupt:
        pass
    finally:
        emu.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
