"""`simlink` drivers: the IMU and the gimbal of a simulator that runs in another process.

`ramp sim mission --realtime` runs the simulated hardware and the arena (the world, the
Hokuyo, IMU and gimbal emulators) in a process of their own and the backend in another, as on
the robot, where the autonomy's computer is not the backend's. The LIDAR already speaks SCIP
over TCP and the backend MCP; the IMU and the gimbal are HAL-level emulators (USB cannot be
emulated, SPEC 6.2), so they reach the autonomy's process over this **sensor link**: one
stream socket (a socketpair or loopback TCP) carrying one JSON object per line, each with its
kind in `"k"`. The simulator's side is `ramp.simulation.arena_process`; this module never
imports it.

- `encode(kind, **fields)` and `decode(buf) -> (used, message)` are the sans-IO codec (0 used:
  need more bytes; a message of None with bytes used: a blank line). A line longer than
  `MAX_FRAME_BYTES`, or one that is not a JSON object with a string `"k"` (nested past the
  parser's depth, or holding a NaN or an infinity, which `encode` never sends), is a
  ProtocolError: the peer is broken, and the link closes (fail closed). A message whose
  fields are wrong (a short row, a string for a number) is refused whole by its handler,
  which changes nothing; the link logs it and goes on.
- `SensorLink` moves the bytes: a non-blocking socket serviced as a reader (and a writer while
  its output is backed up) on the scheduler's loop, so it never blocks a tick; `on(kind, fn)`
  routes the messages. A peer that closes, resets or stops reading closes the link and tells
  `on_close`; nothing is queued once it is closed.
- `SimLinkImu` and `SimLinkPanTilt` behave as the `sim` drivers (`ramp.autonomy.hal.sim`) and
  the `phidget` ones at the HAL: samples come in ticks, commands reach the controller only
  while it is attached and are all sent again when it re-attaches, and a board that is
  unplugged -- or a link that is lost -- is a fault that clears when it comes back.

The messages (simulator -> autonomy):

    {"k": "imu", "attached": true, "s": [[t, ms, ax, ay, az, gx, gy, gz, mx, my, mz], ...]}
    {"k": "gimbal", "attached": true, "pos": [pan, tilt], "reached": [[deg...], [deg...]]}

and (autonomy -> simulator): `imu.open`, `imu.close`, `imu.interval` (`ms`), `imu.zero`, and
`servo` (`axis` pan|tilt, `op` target|velocity|acceleration|engaged, `v`). Samples carry the
simulator's clock time, which is the autonomy's: both read `time.monotonic`, one clock for
every process of the machine.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import select
import socket
from collections.abc import Callable
from typing import Any

from ramp.autonomy.config import GimbalConfig, ImuConfig, ServoConfig
from ramp.autonomy.hal.interfaces import Imu, ImuSample, Servo
from ramp.autonomy.hal.sim import SimulatedGimbal
from ramp.common.tcpclient import IoLoop
from ramp.errors import DeviceError, ProtocolError

log = logging.getLogger(__name__)

#: Longest line accepted (an IMU batch after a hiccup of a second is about 15 kB).
MAX_FRAME_BYTES = 1 << 20
#: Output held for a peer that does not read before the link gives up on it.
MAX_BACKLOG_BYTES = 4 << 20
#: Read at most this much per turn on the loop, so one burst cannot hold a tick back.
READ_CHUNK_BYTES = 1 << 16
READS_PER_TURN = 4

Message = dict[str, Any]
Handler = Callable[[Message], None]
AXES = ("pan", "tilt")
SERVO_OPS = ("target", "velocity", "acceleration", "engaged")


# -- the codec ---------------------------------------------------------------------------------
def encode(kind: str, **fields: Any) -> bytes:
    """One message as its line (floats keep every bit: JSON writes their repr). ValueError,
    naming the kind, for a field that is not JSON: NaN and the infinities never leave."""
    try:
        text = json.dumps({"k": kind, **fields}, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"a {kind!r} message cannot be sent: {exc}") from exc
    return text.encode("utf-8") + b"\n"


def _refuse_constant(name: str) -> Any:
    raise ProtocolError(f"sensor link: {name} in a message (only finite numbers are sent)")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):  # 1e400: a number JSON allows, a float cannot hold
        raise ProtocolError(f"sensor link: {text[:40]} is out of a float's range")
    return value


def decode(buf: bytes | bytearray) -> tuple[int, Message | None]:
    """(bytes used, the message) of the first line in `buf`; (0, None) when it is not whole
    yet. ProtocolError for a line that is too long or not a message (not JSON, nested past
    the parser's depth, a NaN or an infinity: `encode` sends none).

    Only the first line is copied, however long the backlog behind it: the link decodes a
    burst one line at a time from the front of its buffer."""
    end = buf.find(b"\n", 0, MAX_FRAME_BYTES + 1)
    if end < 0:
        if len(buf) > MAX_FRAME_BYTES:
            raise ProtocolError(f"sensor link: a line longer than {MAX_FRAME_BYTES} bytes")
        return 0, None
    line = bytes(buf[:end]).strip()
    if not line:
        return end + 1, None
    try:
        msg = json.loads(line, parse_constant=_refuse_constant, parse_float=_finite_float)
    except ProtocolError:
        raise
    except RecursionError as exc:
        raise ProtocolError(f"sensor link: a line nested too deeply: {line[:60]!r}") from exc
    except (UnicodeDecodeError, ValueError) as exc:
        raise ProtocolError(f"sensor link: not JSON: {line[:60]!r}") from exc
    if not isinstance(msg, dict) or not isinstance(msg.get("k"), str):
        raise ProtocolError(f"sensor link: not a message (an object with a kind \"k\"): "
                            f"{line[:60]!r}")
    return end + 1, msg


# -- the transport -----------------------------------------------------------------------------
class SensorLink:
    """One end of the sensor link over a connected stream socket (see the module docstring).

    With a `loop` (the scheduler) the socket is serviced as a reader between ticks; without
    one, `pump(timeout)` reads what has come (for a caller that waits for its peer before any
    loop runs). Handlers run on the loop's thread, in the order the messages came."""

    def __init__(self, sock: socket.socket, loop: IoLoop | None = None, *,
                 name: str = "sensor link") -> None:
        sock.setblocking(False)
        self.sock = sock
        self.name = name
        self.fd = sock.fileno()
        self._loop: IoLoop | None = None
        self._in = bytearray()
        self._out = bytearray()
        self._writing = False
        self._handlers: dict[str, list[Handler]] = {}
        #: Called once with the reason when the link closes (by either side).
        self.on_close: list[Callable[[str], None]] = []
        self.closed = False
        self.reason = ""
        self.received = 0
        self.sent = 0
        if loop is not None:
            self.attach(loop)

    @property
    def connected(self) -> bool:
        return not self.closed

    def attach(self, loop: IoLoop) -> None:
        """Service the socket on `loop` from now on."""
        if self.closed:
            return
        self._loop = loop
        loop.add_reader(self.fd, self.on_readable)
        if self._out:
            self._writing = True
            loop.add_writer(self.fd, self.on_writable)

    def on(self, kind: str, handler: Handler) -> None:
        """Route messages of `kind` to `handler(message)`."""
        self._handlers.setdefault(kind, []).append(handler)

    # -- sending -----------------------------------------------------------------------------
    def send(self, kind: str, **fields: Any) -> bool:
        """Queue one message and write what the socket takes now; False once closed.
        ValueError, naming the link and the kind, for a message that is not JSON (nothing
        is queued: the link goes on)."""
        if self.closed:
            return False
        try:
            line = encode(kind, **fields)
        except ValueError as exc:
            raise ValueError(f"{self.name}: {exc}") from exc
        self._out += line
        self.sent += 1
        self._flush()
        return not self.closed

    def _flush(self) -> None:
        while self._out and not self.closed:
            try:
                n = self.sock.send(self._out)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                self.close(f"the peer is gone ({exc.strerror or exc})")
                return
            del self._out[:n]
        if self.closed:
            return
        if len(self._out) > MAX_BACKLOG_BYTES:
            self.close(f"the peer has not read {len(self._out)} bytes")
            return
        want = bool(self._out)
        if want != self._writing and self._loop is not None:
            self._writing = want
            if want:
                self._loop.add_writer(self.fd, self.on_writable)
            else:
                self._loop.remove_writer(self.fd)

    def on_writable(self) -> None:
        self._flush()

    def drain(self, timeout_s: float) -> bool:
        """Wait up to `timeout_s` for the queued output to leave (at the end of a run, when
        no loop turns any more); True when it has."""
        if self.closed:
            return False
        self._flush()
        while self._out and not self.closed and timeout_s > 0:
            _, w, _ = select.select([], [self.fd], [], min(timeout_s, 0.05))
            timeout_s -= 0.05
            if w:
                self._flush()
        return not self._out and not self.closed

    # -- receiving ---------------------------------------------------------------------------
    def on_readable(self) -> None:
        """Read what has come (a bounded amount per turn) and dispatch every whole line."""
        for _ in range(READS_PER_TURN):
            if self.closed:
                return
            try:
                chunk = self.sock.recv(READ_CHUNK_BYTES)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                self.close(f"the peer is gone ({exc.strerror or exc})")
                return
            if not chunk:
                self._dispatch()
                self.close("the peer closed the link")
                return
            self._in += chunk
            self._dispatch()

    def pump(self, timeout_s: float) -> None:
        """Without a loop: wait up to `timeout_s` for input, then read and dispatch it."""
        if self.closed:
            return
        r, _, _ = select.select([self.fd], [], [], max(0.0, timeout_s))
        if r:
            self.on_readable()

    def _dispatch(self) -> None:
        while self._in and not self.closed:
            try:
                used, msg = decode(self._in)
            except ProtocolError as exc:
                self.close(str(exc))
                return
            if used == 0:
                return
            del self._in[:used]
            if msg is None:
                continue
            self.received += 1
            for handler in self._handlers.get(msg["k"], ()):
                try:
                    handler(msg)
                except Exception:  # noqa: BLE001 - one bad message must not end the link
                    log.exception("%s: handling a %r message failed", self.name, msg["k"])

    # -- the end -----------------------------------------------------------------------------
    def close(self, reason: str = "closed") -> None:
        """Close the socket and tell `on_close`; safe to call twice."""
        if self.closed:
            return
        self.closed = True
        self.reason = reason
        if self._loop is not None:
            self._loop.remove_reader(self.fd)
            if self._writing:
                self._loop.remove_writer(self.fd)
        self._writing = False
        self._out.clear()
        with contextlib.suppress(OSError):
            self.sock.close()
        if reason != "closed":
            log.info("%s: closed: %s", self.name, reason)
        for fn in list(self.on_close):
            try:
                fn(reason)
            except Exception:  # noqa: BLE001 - every listener hears it
                log.exception("%s: a close listener raised", self.name)


def _floats(values: Any, n: int, what: str) -> tuple[float, ...]:
    """`n` finite numbers (not bools) from the list `values`; ValueError naming `what`."""
    if not isinstance(values, list) or len(values) != n or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in values):
        raise ValueError(f"{what}: expected {n} finite numbers, got {values!r:.80}")
    return tuple(float(v) for v in values)


def sample_row(s: Any) -> list[float]:
    """An IMU emulator's sample (t, timestamp_ms, acceleration, angular_rate,
    magnetic_field) as the row an `imu` message carries."""
    row = [float(s.t), float(s.timestamp_ms), *map(float, s.acceleration),
           *map(float, s.angular_rate)]
    if s.magnetic_field is not None:
        row.extend(map(float, s.magnetic_field))
    return row


def parse_sample(row: Any, who: str = "imu") -> ImuSample:
    """An `imu` message's row as a sample; ValueError, naming the device `who`, when it is
    not one."""
    if not isinstance(row, list) or len(row) not in (8, 11):
        raise ValueError(f"{who}: an IMU sample is 8 or 11 numbers, got {row!r:.80}")
    v = _floats(row, len(row), f"{who}: an IMU sample")
    mag = (v[8], v[9], v[10]) if len(v) == 11 else None
    return ImuSample(t=v[0], timestamp_ms=v[1], accel_g=(v[2], v[3], v[4]),
                     gyro_dps=(v[5], v[6], v[7]), mag_gauss=mag)


def _attached(msg: Message, who: str) -> bool:
    attached = msg.get("attached")
    if not isinstance(attached, bool):
        raise ValueError(f"{who}: \"attached\" is not true or false: {attached!r:.40}")
    return attached


# -- the drivers -------------------------------------------------------------------------------
class SimLinkImu(Imu):
    """The simulated PhidgetSpatial, over the sensor link."""

    driver_name = "simlink"

    def __init__(self, config: ImuConfig, name: str = "imu", *, link: SensorLink) -> None:
        super().__init__(config, name)
        self.link = link
        self._board = False  # the board is attached, as the last message said
        self._pending: list[ImuSample] = []
        link.on("imu", self._on_imu)

    def _on_imu(self, msg: Message) -> None:
        """The whole message is checked before any of it is taken: a bad one changes
        nothing (the link logs it and goes on)."""
        if not self.is_open:
            return
        board = _attached(msg, self.name)
        rows = msg.get("s", [])
        if not isinstance(rows, list):
            raise ValueError(f"{self.name}: \"s\" is not a list of samples: {rows!r:.80}")
        samples = [parse_sample(row, self.name) for row in rows]
        self._board = board
        for sample in samples:
            if len(self._pending) >= self.MAX_BUFFER:
                del self._pending[0]
                self.dropped += 1
            self._pending.append(sample)

    def _open(self, now: float) -> None:
        self._attached = False
        self._board = False
        self._pending.clear()
        self.link.send("imu.open")  # what was measured while nobody listened is gone

    def _tick(self, now: float, dt: float) -> None:
        there = self.link.connected and self._board
        if there and not self._attached:
            self.link.send("imu.interval", ms=self.config.data_interval_ms)
            self._attach(now)
            log.info("%s: simulated PhidgetSpatial attached (sensor link)", self.name)
        elif not there and self._attached:
            self._detach("simulated PhidgetSpatial detached" if self.link.connected
                         else f"sensor link lost: {self.link.reason}")
        if not self._attached:
            self._pending.clear()
            return
        pending, self._pending = self._pending, []
        for sample in pending:
            self._accept(sample, now)

    def _zero_gyro(self) -> None:
        self.link.send("imu.zero")

    def _close(self) -> None:
        self._attached = False
        self._pending.clear()
        self.link.send("imu.close")


class SimLinkServo(Servo):
    """One axis of `SimLinkPanTilt`: its commands go over the link while attached."""

    def __init__(self, gimbal: SimLinkPanTilt, config: ServoConfig) -> None:
        super().__init__(gimbal.name, config)
        self.gimbal = gimbal

    def _live(self) -> bool:
        return self.gimbal.is_open and self.attached

    def _send(self, op: str, value: float | bool) -> None:
        self.gimbal.link.send("servo", axis=self.config.name, op=op, v=value)

    def _apply_target(self, deg: float) -> None:
        if self._live():
            self._send("target", deg)

    def _apply_velocity_limit(self, dps: float) -> None:
        if self._live():
            self._send("velocity", dps)

    def _apply_acceleration(self, dps2: float) -> None:
        if self._live():
            self._send("acceleration", dps2)

    def _apply_engaged(self, on: bool) -> None:
        if self._live():
            self._send("engaged", on)

    def _send_all(self) -> None:
        """Everything the controller forgot at its power-on."""
        self._send("velocity", self.velocity_limit_dps)
        self._send("acceleration", self.acceleration_dps2)
        if self.target_deg is not None:
            self._send("target", self.target_deg)
            if self.engaged:
                self._send("engaged", True)


class SimLinkPanTilt(SimulatedGimbal):
    """The simulated PhidgetAdvancedServo and its two servos, over the sensor link."""

    driver_name = "simlink"

    def __init__(self, config: GimbalConfig, name: str = "gimbal", *,
                 link: SensorLink) -> None:
        self.link = link
        self._board = False
        self._positions: list[float | None] = [None, None]
        self._reached: tuple[list[float], list[float]] = ([], [])
        super().__init__(config, name)
        link.on("gimbal", self._on_gimbal)

    def _make_servo(self, config: ServoConfig) -> Servo:
        if config.name not in AXES:
            raise ValueError(f"{self.name}: a servo named {config.name!r}; expected pan, tilt")
        return SimLinkServo(self, config)

    def _axes(self) -> tuple[SimLinkServo, SimLinkServo]:
        pan, tilt = self.pan, self.tilt
        assert isinstance(pan, SimLinkServo) and isinstance(tilt, SimLinkServo)
        return (pan, tilt)

    def _on_gimbal(self, msg: Message) -> None:
        """The whole message is checked before any of it is taken: a bad one changes
        nothing (the link logs it and goes on)."""
        if not self.is_open:
            return
        board = _attached(msg, self.name)
        pos = msg.get("pos", [None, None])
        reached = msg.get("reached", [[], []])
        if not isinstance(pos, list) or len(pos) != 2:
            raise ValueError(f"{self.name}: \"pos\" is not [pan, tilt]: {pos!r:.80}")
        if not isinstance(reached, list) or len(reached) != 2 \
                or not all(isinstance(r, list) for r in reached):
            raise ValueError(f"{self.name}: \"reached\" is not [[pan...], [tilt...]]: "
                             f"{reached!r:.80}")
        positions = [None if p is None else _floats([p], 1, f"{self.name} {axis}: position")[0]
                     for axis, p in zip(AXES, pos, strict=True)]
        events = [_floats(r, len(r), f"{self.name} {axis}: target reached")
                  for axis, r in zip(AXES, reached, strict=True)]
        self._board = board
        self._positions = positions
        for i in range(2):
            self._reached[i].extend(events[i])

    def _open(self, now: float) -> None:
        self._board = False
        self._positions = [None, None]
        for i, axis in enumerate(self._axes()):
            axis.attached = False
            axis.position_deg = None
            self._reached[i].clear()

    def _tick(self, now: float, dt: float) -> None:
        there = self.link.connected and self._board
        for i, axis in enumerate(self._axes()):
            if there and not axis.attached:
                self._reached[i].clear()  # news of what the old controller did
            if not self._follow_controller(axis, there, " (sensor link)"):
                self._reached[i].clear()
                continue
            reached, self._reached[i][:] = list(self._reached[i]), []
            for deg in reached:
                axis._report_reached(deg)
            if axis.engaged:
                pos = self._positions[i]
                if pos is not None:
                    axis._report_position(pos)

    def _detached(self, axis: Any) -> DeviceError:
        if not self.link.connected:
            return DeviceError(self.name, f"sensor link lost: {self.link.reason}", axis.label)
        return super()._detached(axis)

    def _close(self) -> None:
        for i, axis in enumerate(self._axes()):
            axis.attached = False
            axis.position_deg = None
            self._reached[i].clear()
