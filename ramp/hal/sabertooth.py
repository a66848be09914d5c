"""`sabertooth` driver: Dimension Engineering Sabertooths on one packetized-serial line.

Up to eight controllers (addresses 128-135, two motors each) share one TX wire; nothing comes
back. The wire is slow (9600 baud carries 240 packets/s), so this driver is mostly a pacer:

- **Newest wins.** A changed channel is only marked pending; its packet is built from the
  channel's duty when it is sent, so a burst of requests never builds a backlog of stale
  commands (and the driver keeps no copy of the commanded value, only what is on the wire).
- **Changes first, at once.** `set_duty` marks the channel pending and writes it straight
  away when the budget allows, so a request is on the wire before the next tick.
- **Budget.** A token bucket of `baud/10 - 32` bytes/s holding at most 32 bytes: any one
  second carries at most 32 + (baud/10 - 32) = baud/10 bytes, bursts stay <= 32 bytes, and a
  sustained stream of changes keeps the wire > 90 % busy at 9600 and 19200 baud. The bucket
  refills only in `tick`, so at 100 Hz at most 32 bytes go per tick (3200 B/s): 83 % of
  38400 baud, 28 % of 115200.
- **Shallow queue.** The driver models the wire: it knows when the bytes it already wrote will
  have left the UART, and writes more only while less than one tick of wire time is queued.
  A 32-byte burst would otherwise sit 33 ms in the OS buffer at 9600 baud, and a newer command
  would wait behind stale ones; this way "newest wins" holds down to the wire.
- **Refresh.** Every channel is re-sent at least twice per controller timeout, so the
  controller's own timeout (command 14, programmed at open) fires only when the supervisor
  is gone or the cable is cut. A refresh normally waits behind changes; one that is late
  jumps the queue, so a flood on some channels cannot let another controller time out.
- **Reprogramming.** Command 14 does not survive a controller power cycle (a motor-battery
  brown-out), so it is re-sent every few seconds with whatever budget is left.

Writes never block the tick: the port is opened with `write_timeout=0` and written only when
`select` says it has room; a short write keeps the packet's tail, which goes out before
anything else, so the controller never sees half a packet followed by a new one. Only
`open` (start-up programming) and `stop_motors` (safety beats the budget) may wait briefly
for the OS buffer; both still charge their bytes to the budget.

Errors: a write that fails inside `set_duty` is remembered (`failure`) and raised by the
next `tick` as a `DeviceError` naming the bus (a request handler never sees an I/O
exception). A Sabertooth never talks back, so a readable port means a hang-up: `tick` looks
for one (a zero-timeout `select`), so an unplugged adapter is noticed within one tick. (The
port is not in the loop's wait: the kernel would poll the tty at every request answered.)

Every packet a channel can send is built once, when the channel is (`SabertoothMotor`), with
the codec's checks; sending is then a table lookup.
"""

from __future__ import annotations

import contextlib
import math
import select
import sys
from collections.abc import Mapping
from typing import Any, ClassVar, Final

import serial

from ramp.errors import ConfigError, DeviceError
from ramp.hal import sabertooth_codec as codec
from ramp.hal.interfaces import Bus, MotorChannel
from ramp.schema import Field

#: Largest burst, in bytes, the pacer writes back to back (8 packets).
BURST_BYTES: Final = 32
#: How often command 14 is re-sent to every controller, in seconds.
REPROGRAM_PERIOD_S: Final = 2.0
#: Margin kept between a refresh and half the controller timeout (tick jitter, wire time).
REFRESH_SLACK_S: Final = 0.05
#: `open`/`stop_motors` wait at most this many times this long for room in the OS buffer.
_BLOCKING_TRIES: Final = 10
_BLOCKING_WAIT_S: Final = 0.02
#: pyserial handlers that live in-process and have no file descriptor to poll.
_IN_PROCESS_URLS: Final = ("loop://",)
#: Commands whose data byte is a motor speed (0 = stop).
_MOTOR_COMMANDS: Final = (codec.CMD_M1_FORWARD, codec.CMD_M1_BACKWARD, codec.CMD_M2_FORWARD,
                          codec.CMD_M2_BACKWARD)

Key = tuple[int, int]  # (address, motor)


class SabertoothMotor(MotorChannel):
    """One motor output of one controller, with every packet it can send built once."""

    def __init__(self, bus: SabertoothBus, label: str, address: int, motor: int) -> None:
        super().__init__(bus, label)
        self.address = address
        self.motor = motor
        self.key: Key = (address, motor)
        forward, _ = codec.duty_command(motor, 0.0)
        #: Packets by speed byte 0..127, forward and backward (the codec checks them here).
        self._forward = [codec.encode(address, forward, s) for s in range(128)]
        self._backward = [codec.encode(address, forward + 1, s) for s in range(128)]
        self.zero = self._forward[0]

    def packet(self) -> bytes:
        """The packet for the duty commanded now, as `codec.encode_motor` builds it."""
        duty = self.duty
        if duty < 0:
            return self._backward[round(-duty * 127)]
        return self._forward[round(duty * 127)]


class SabertoothBus(Bus):
    """One serial line (a USB-TTL adapter, a pty or any pyserial URL) with Sabertooths on it."""

    driver_name = "sabertooth"
    fields: ClassVar[dict[str, Field]] = {
        "port": Field(str, what="a serial device path or pyserial URL"),
        "baud": Field(int, default=9600, choices=(2400, 9600, 19200, 38400, 115200),
                      what="a Sabertooth baud rate"),
        "timeout": Field(float, default=0.5, lo=0.1, hi=12.7,
                         what="a controller serial timeout in seconds"),
        "autobaud": Field(bool, default=False),
        "exclusive": Field(bool, default=True),
    }
    channel_fields: ClassVar[dict[str, dict[str, Field]]] = {
        "motor": {
            "address": Field(int, lo=128, hi=135, what="a Sabertooth address"),
            "motor": Field(int, choices=(1, 2), what="a Sabertooth motor number"),
        }
    }

    def __init__(self, name: str, params: Mapping[str, Any]) -> None:
        super().__init__(name, params)
        cfg = self.check_params(params)
        self.port: str = cfg["port"]
        self.baud: int = cfg["baud"]
        self.timeout_s: float = cfg["timeout"]
        self.autobaud: bool = cfg["autobaud"]
        self.exclusive: bool = cfg["exclusive"]
        #: Bytes per second the pacer may use on top of one burst (see module docstring).
        self.rate = self.baud / 10 - BURST_BYTES
        #: Wire time of one byte (8N1: 10 bits), and how much may wait in the OS buffer.
        self._byte_time = 10.0 / self.baud
        self._queue_limit = 0.01
        slack = min(REFRESH_SLACK_S, self.timeout_s / 4)
        #: A channel is re-sent once its last packet is this old ...
        self.refresh_period = self.timeout_s / 2 - slack
        #: ... and jumps ahead of changes once it is this old.
        self.urgent_age = self.timeout_s / 2 - slack / 2
        self.stats: dict[str, int] = {
            "bytes_sent": 0, "packets_sent": 0, "max_pending": 0, "refreshes": 0,
            "budget_waits": 0, "short_writes": 0, "forced_bytes": 0,
        }
        self._channels: dict[Key, SabertoothMotor] = {}
        self._ser: Any = None
        self._fd: int | None = None
        self._room_cap: int | None = None  # in-process handlers: their queue size
        #: The port's descriptor, kept registered for the per-tick hang-up look.
        self._alive: select.poll | None = None
        self._now = 0.0
        self._reset_state()

    def _reset_state(self) -> None:
        #: Channels whose duty changed and is not on the wire yet, in order of change (the
        #: packet is built from the channel when it is sent: newest wins by construction).
        self._pending: dict[Key, None] = {}
        self._sent: dict[Key, bytes] = {}
        self._sent_at: dict[Key, float] = {}
        self._programmed_at: dict[int, float] = {}
        self._tail = b""
        self._tail_packet = b""  # the motor packet `_tail` finishes (b"" when not one)
        self._tokens = float(BURST_BYTES)
        self._refilled_at = self._now
        self._wire_free_at = self._now  # when the bytes written so far will have left
        self._due_at = -math.inf  # next refresh or reprogramming; -inf: to be worked out

    # -- channels -----------------------------------------------------------------------------
    def _make_channel(self, kind: str, label: str, spec: dict[str, Any]) -> Any:
        address, motor = int(spec["address"]), int(spec["motor"])
        key = (address, motor)
        if key in self._channels:
            other = self._channels[key].label
            raise ConfigError(
                f"{label} and {other} both use address {address} motor {motor}",
                key=f"buses.{self.name}",
            )
        ch = SabertoothMotor(self, label, address, motor)
        self._channels[key] = ch
        return ch

    @property
    def addresses(self) -> list[int]:
        """Controller addresses that have at least one channel, ascending."""
        return sorted({a for a, _ in self._channels})

    # -- lifecycle ----------------------------------------------------------------------------
    def _open(self, now: float) -> None:
        self._now = now
        self._reset_state()
        self._refilled_at = now
        is_url = "://" in self.port
        in_process = self.port.lower().startswith(_IN_PROCESS_URLS)
        try:
            ser = serial.serial_for_url(
                self.port, baudrate=self.baud, timeout=0,
                # loop:// emulates wire time and fails every write when write_timeout=0;
                # it never blocks as long as we respect its queue size (checked in _room).
                write_timeout=None if in_process else 0,
                do_not_open=True,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceError(self.name, f"cannot open {self.port}: {exc}") from exc
        try:
            if self.exclusive and not is_url:
                ser.exclusive = True
            ser.open()
        except (serial.SerialException, OSError, ValueError) as exc:
            _release(ser)
            raise DeviceError(self.name, f"cannot open {self.port}: {exc}") from exc
        self._ser = ser
        self._fd, self._alive = None, None
        self._room_cap = None
        try:
            self._fd = ser.fileno()
            self._alive = select.poll()
            self._alive.register(self._fd, select.POLLIN)
        except (AttributeError, OSError, ValueError):
            self._room_cap = getattr(ser, "buffer_size", None) if in_process else None
        start = bytearray()
        if self.autobaud:
            start.append(codec.AUTOBAUD)
        for address in self.addresses:
            start += codec.encode_timeout(address, self.timeout_s)
            self._programmed_at[address] = now
        for key, ch in self._channels.items():
            start += ch.zero
            self._sent[key] = ch.zero
            self._sent_at[key] = now
        self.stats["packets_sent"] += len(start) // codec.PACKET_LEN
        try:
            self._write_blocking(bytes(start))
            if self._fd is not None and not is_url:
                ser.flush()  # tcdrain: on a real UART, wait until the bytes have left
            self._wire_free_at = self._now  # drained (or a URL handler): nothing queued
        except DeviceError:
            self._close()
            raise
        except (serial.SerialException, OSError) as exc:
            self._close()
            raise DeviceError(self.name, f"cannot write to {self.port}: {exc}") from exc

    def _tick(self, now: float, dt: float) -> None:
        self._now = now
        if dt > 0:
            self._queue_limit = max(self._byte_time * codec.PACKET_LEN, dt)
        elapsed = max(0.0, now - self._refilled_at)
        self._tokens = min(float(BURST_BYTES), self._tokens + self.rate * elapsed)
        self._refilled_at = now
        self._check_alive()
        if self._pending or self._tail or now >= self._next_due():
            self._pump()
        if self.failure is not None:
            raise self.failure

    def _next_due(self) -> float:
        """When the next refresh or reprogramming falls due (worked out again only after a
        packet went out), so an idle tick costs a comparison, not a scan."""
        if self._due_at == -math.inf:
            refresh = min(self._sent_at.values(), default=math.inf) + self.refresh_period
            program = min(self._programmed_at.values(), default=math.inf) + REPROGRAM_PERIOD_S
            self._due_at = min(refresh, program)
        return self._due_at

    def output_queued(self) -> bool:
        """Packets waiting for the wire's budget, or a packet half written."""
        return bool(self._pending or self._tail)

    # No `fileno()` for the loop to watch: a tty in the loop's wait is polled by the kernel
    # at every wake-up (every request answered), which costs more than one look per tick.

    def _stop_motors(self) -> None:
        """Zeros for every channel, written now whatever the budget: stopping is a safety
        action, and a few dozen bytes over budget once is harmless. Any half-written packet
        is finished first so the zeros are not swallowed by a broken packet; a motor command
        is finished as speed 0, so nothing queued before the stop moves a motor."""
        self._pending.clear()
        data = bytearray(self._tail_as_stop())
        self._tail, self._tail_packet = b"", b""
        for key, ch in self._channels.items():
            data += ch.zero
            self._sent[key] = ch.zero
            self._sent_at[key] = self._now
            self.stats["packets_sent"] += 1
        self._due_at = -math.inf
        self._write_blocking(bytes(data))

    def _tail_as_stop(self) -> bytes:
        """The rest of a half-written packet. Its address (and maybe command) byte is out, so
        it must be completed; a motor command is completed with speed 0 and its checksum."""
        tail, packet = self._tail, self._tail_packet
        if not tail or not packet or packet[1] not in _MOTOR_COMMANDS:
            return tail
        return codec.encode(packet[0], packet[1], 0)[len(packet) - len(tail):]

    def _close(self) -> None:
        ser, self._ser, self._fd, self._alive = self._ser, None, None, None
        self._tail, self._tail_packet = b"", b""
        self._pending.clear()
        if ser is not None:
            _release(ser)

    # -- pacing -------------------------------------------------------------------------------
    def _motor_changed(self, ch: MotorChannel) -> None:
        """A channel's duty changed: mark it (the newest value is read when it is sent) unless
        the controller already has it, then send what fits."""
        assert isinstance(ch, SabertoothMotor)
        if ch.packet() == self._sent.get(ch.key):
            self._pending.pop(ch.key, None)  # the controller already has this value
        else:
            self._pending[ch.key] = None  # an existing key keeps its place in the order
            self.stats["max_pending"] = max(self.stats["max_pending"], len(self._pending))
        if self.failure is None:
            self._pump()

    def _next_packet(self) -> bytes | None:
        """The packet to send next, or None when nothing is due."""
        now = self._now
        oldest: Key | None = None
        for key in self._channels:
            if oldest is None or self._sent_at.get(key, -1e18) < self._sent_at.get(oldest, -1e18):
                oldest = key
        oldest_age = now - self._sent_at.get(oldest, -1e18) if oldest is not None else 0.0
        if oldest is not None and oldest_age >= self.urgent_age:
            if self._pending.pop(oldest, 0) is None:
                return self._mark_sent(oldest, self._channels[oldest].packet())
            self.stats["refreshes"] += 1
            return self._mark_sent(oldest, self._sent[oldest])
        if self._pending:
            key = next(iter(self._pending))
            del self._pending[key]
            return self._mark_sent(key, self._channels[key].packet())
        if oldest is not None and oldest_age >= self.refresh_period:
            self.stats["refreshes"] += 1
            return self._mark_sent(oldest, self._sent[oldest])
        for address, at in self._programmed_at.items():
            if now - at >= REPROGRAM_PERIOD_S:
                self._programmed_at[address] = now
                self._due_at = -math.inf
                return codec.encode_timeout(address, self.timeout_s)
        return None

    def _mark_sent(self, key: Key, pkt: bytes) -> bytes:
        self._sent[key] = pkt
        self._sent_at[key] = self._now
        self._due_at = -math.inf
        return pkt

    def _pump(self) -> None:
        """Write what the budget and the OS buffer allow; never waits."""
        if self._ser is None:
            return
        try:
            if self._tail:
                n = self._write_some(self._tail)
                self._tail = self._tail[n:]
                if self._tail:
                    return
                self._tail_packet = b""
            while True:
                if self._tokens < codec.PACKET_LEN:
                    if self._pending or self._something_due():
                        self.stats["budget_waits"] += 1
                    return
                if self._wire_free_at - self._now >= self._queue_limit:
                    return  # enough is queued; what comes next may still be superseded
                pkt = self._next_packet()
                if pkt is None:
                    return
                self._tokens -= len(pkt)
                self.stats["packets_sent"] += 1
                n = self._write_some(pkt)
                if n < len(pkt):
                    self._tail, self._tail_packet = pkt[n:], pkt
                    self.stats["short_writes"] += 1
                    return
        except DeviceError as exc:
            self.failure = exc

    def _something_due(self) -> bool:
        now = self._now
        return any(now - at >= self.refresh_period for at in self._sent_at.values())

    # -- raw I/O ------------------------------------------------------------------------------
    def _room(self) -> bool:
        """True when a write will take at least one byte without blocking."""
        if self._fd is not None:
            _, writable, _ = select.select([], [self._fd], [], 0)
            return bool(writable)
        if self._room_cap is not None:
            return bool(self._ser.out_waiting < self._room_cap)
        return True  # other handlers honour write_timeout=0 themselves

    def _write_some(self, data: bytes) -> int:
        """Write what the port takes now; returns the count. Errors become DeviceError.

        The `select` guard matters: pyserial 3.5's `write` with `write_timeout=0` spins
        forever if the OS answers EAGAIN, so it is only called when there is room.
        """
        ser = self._ser
        if ser is None:
            raise DeviceError(self.name, f"{self.port} is not open")
        try:
            if not self._room():
                return 0
            if self._room_cap is not None:
                data = data[: max(0, self._room_cap - ser.out_waiting)]
            n = ser.write(data) or 0
        except serial.SerialTimeoutException:
            n = 0
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceError(self.name, f"write to {self.port} failed: {exc}") from exc
        self.stats["bytes_sent"] += n
        self._wire_free_at = max(self._now, self._wire_free_at) + n * self._byte_time
        return int(n)

    def _write_blocking(self, data: bytes) -> None:
        """Put `data` in the OS buffer, waiting briefly for room; charged to the budget."""
        self._tokens -= len(data)
        self.stats["forced_bytes"] += len(data)
        rest = data
        idle = 0
        while idle < _BLOCKING_TRIES:  # give up only after this many tries without progress
            n = self._write_some(rest)
            rest = rest[n:]
            if not rest:
                return
            idle = 0 if n else idle + 1
            if self._fd is not None:
                try:
                    select.select([], [self._fd], [], _BLOCKING_WAIT_S)
                except (OSError, ValueError) as exc:
                    raise DeviceError(self.name, f"{self.port} failed: {exc}") from exc
        self._tail, self._tail_packet = rest, b""  # finished by the next pump, first
        raise DeviceError(self.name, f"{self.port} does not take bytes (output stalled)")

    def _check_alive(self) -> None:
        """Notice an unplugged adapter within one tick even when nothing is due to be sent.

        A Sabertooth never talks back, so a readable port means a hang-up (or line noise,
        which is read and dropped). One `poll(0)` on a poller kept while the port is open:
        the idle tick's one system call, without building a descriptor set each time."""
        alive = self._alive
        if alive is None or self._ser is None:
            return
        try:
            if alive.poll(0):  # POLLIN, or POLLHUP/POLLERR/POLLNVAL: the read says which
                self._ser.read(256)
        except (serial.SerialException, OSError, ValueError) as exc:
            self.failure = DeviceError(self.name, f"{self.port} vanished: {exc}")
            raise self.failure from exc


def _release(ser: Any) -> None:
    """Close a port and anything its URL handler opened: `spy://...?file=` opens a log file
    that pyserial never closes, which would leak one descriptor per hot-plug reconnect."""
    # An unplugged port may fail to close; there is nothing left to release then.
    with contextlib.suppress(serial.SerialException, OSError):
        ser.close()
    output = getattr(getattr(ser, "formatter", None), "output", None)
    if output is not None and output not in (sys.stderr, sys.stdout):
        with contextlib.suppress(OSError):
            output.close()
