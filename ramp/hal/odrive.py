"""`can` driver: ODrive motor controllers (firmware 0.5.x) over CAN Simple, via python-can.

One bus entry is one CAN interface; each motor device names an ODrive axis by its node id.
The driver keeps every axis in velocity control with ramped input and maps duty to velocity
(`vel = duty * max_vel`, turns/s), so a wheel moves from YAML to a CAN drive with no change in
the layers above.

Why it looks the way it does:
- Nothing blocks the tick: received frames are drained with `recv(timeout=0)` in a bounded loop
  (no `Notifier`, whose thread would mutate state behind the scheduler's back) and sends use
  `timeout=0`, so a full transmit queue is an error, not a stall.
- Set_Input_Vel goes out at once on a change and again every `refresh` seconds, so an ODrive
  with its own watchdog enabled (`axis.config.enable_watchdog`) stops if the supervisor dies;
  set that watchdog longer than `refresh`.
- An axis is trusted only while its heartbeats are fresh, error-free and in
  CLOSED_LOOP_CONTROL. After open, each axis has a grace period to report closed loop; after
  that a stale heartbeat, an axis error or a drop out of closed loop raises `DeviceError`
  naming bus and node, which the supervisor turns into a module fault.
- The ODrive's own velocity and current limits (`Set_Limits`) are left to its saved
  configuration: the driver knows neither the motor nor the supply.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import can

from ramp.errors import ConfigError, DeviceError
from ramp.hal import odrive_codec as oc
from ramp.hal.interfaces import Bus, MotorChannel
from ramp.schema import Field

#: Most frames one drain reads, so a babbling bus cannot hold the tick (64 axes x 110 frames/s
#: at a 100 Hz tick is about 70 frames per tick).
MAX_DRAIN = 512
#: Float slack, so a tick that lands on a refresh time (virtual clocks do) is not one tick late.
_EPS = 1e-6
#: Shortest time an axis gets after open to report CLOSED_LOOP_CONTROL.
MIN_GRACE = 1.0


class _Motor(MotorChannel):
    """A motor channel bound to one ODrive axis."""

    def __init__(self, bus: ODriveBus, label: str, node_id: int) -> None:
        super().__init__(bus, label)
        self.node_id = node_id


@dataclass
class _Node:
    """What the driver knows about one axis."""

    node_id: int
    channel: _Motor  # its duty is the commanded value; the node keeps only wire state
    dirty: bool = False
    next_refresh: float = 0.0
    last_heartbeat: float | None = None
    axis_state: int = oc.AxisState.UNDEFINED
    axis_error: int = 0
    up: bool = False  # has reported CLOSED_LOOP_CONTROL since open
    encoder: tuple[float, float] | None = None
    bus_voltage: float | None = None

    @property
    def label(self) -> str:
        return self.channel.label

    @property
    def who(self) -> str:
        return f"node {self.node_id} ({self.label})"


class ODriveBus(Bus):
    """ODrive axes on one CAN interface (`interface: socketcan, channel: can0` on the robot,
    `interface: virtual` with the emulator in tests and under `--sim`)."""

    driver_name = "can"
    fields: ClassVar[dict[str, Field]] = {
        # python-can's own list (plugins included): an unknown name passed the check, then
        # the bus retried "Unknown interface type" once a second for ever.
        "interface": Field(str, "virtual", choices=tuple(sorted(can.interfaces.VALID_INTERFACES)),
                           what="a python-can interface name"),
        "channel": Field(str, what="a CAN channel (can0, or any name on virtual)"),
        "bitrate": Field(int, 500000, lo=10000, hi=1000000, what="a CAN bitrate in bit/s"),
        "heartbeat_timeout": Field(float, 0.5, lo=0.05, hi=10.0,
                                   what="a heartbeat timeout in s"),
        "max_vel": Field(float, 10.0, lo=0.001, hi=1000.0,
                         what="a velocity in turns/s at duty 1.0"),
        "refresh": Field(float, 0.05, lo=0.001, hi=5.0,
                         what="a Set_Input_Vel refresh period in s"),
    }
    channel_fields: ClassVar[dict[str, dict[str, Field]]] = {
        "motor": {"node_id": Field(int, lo=0, hi=63, what="an ODrive node id")},
    }

    def __init__(self, name: str, params: Mapping[str, Any]) -> None:
        super().__init__(name, params)
        cfg = self.check_params(params)
        self.interface: str = cfg["interface"]
        self.can_channel: str = cfg["channel"]
        self.bitrate: int = cfg["bitrate"]
        self.heartbeat_timeout: float = cfg["heartbeat_timeout"]
        self.max_vel: float = cfg["max_vel"]
        self.refresh: float = cfg["refresh"]
        self.grace = max(MIN_GRACE, self.heartbeat_timeout)
        self._nodes: dict[int, _Node] = {}
        self._bus: can.BusABC | None = None
        self._opened_at = 0.0
        self._now = 0.0
        #: Frame counters: sent, recv (all), ignored (not ours or not used), bad (undecodable).
        self.stats: dict[str, int] = {"sent": 0, "recv": 0, "ignored": 0, "bad": 0}

    # -- channels -------------------------------------------------------------------------------
    def _make_channel(self, kind: str, label: str, spec: dict[str, Any]) -> Any:
        node_id = spec["node_id"]
        if node_id in self._nodes:
            raise ConfigError(
                f"node_id {node_id} is already used by {self._nodes[node_id].label} "
                f"on bus {self.name}", key=label)
        channel = _Motor(self, label, node_id)
        self._nodes[node_id] = _Node(node_id, channel)
        return channel

    # -- queries --------------------------------------------------------------------------------
    def encoder(self, node_id: int) -> tuple[float, float] | None:
        """Newest (position turns, velocity turns/s) of an axis, or None before the first."""
        node = self._nodes.get(node_id)
        return None if node is None else node.encoder

    def axis(self, node_id: int) -> tuple[int, int] | None:
        """Newest (axis_state, axis_error) from the heartbeat, or None before the first."""
        node = self._nodes.get(node_id)
        if node is None or node.last_heartbeat is None:
            return None
        return node.axis_state, node.axis_error

    def bus_voltage(self, node_id: int) -> float | None:
        """Newest DC bus voltage an axis answered with (see `request_bus_voltage`)."""
        node = self._nodes.get(node_id)
        return None if node is None else node.bus_voltage

    def request_bus_voltage(self, node_id: int) -> None:
        """Ask an axis for its bus voltage (RTR); the answer arrives in a later tick."""
        if self._bus is not None and node_id in self._nodes:
            self._send(node_id, oc.Cmd.GET_BUS_VOLTAGE, b"", remote=True)

    def ready(self) -> bool:
        """Open and every axis has reported CLOSED_LOOP_CONTROL."""
        return self.is_open and all(n.up for n in self._nodes.values())

    def fileno(self) -> int | None:
        """The socket of socketcan, so the scheduler drains between ticks; None on virtual."""
        if self._bus is None:
            return None
        try:
            fd = self._bus.fileno()
        except NotImplementedError:
            return None
        return fd if isinstance(fd, int) and fd >= 0 else None

    def on_readable(self, now: float) -> None:
        try:
            self._drain(now)
        except DeviceError as exc:
            self.failure = self.failure or exc

    # -- lifecycle ------------------------------------------------------------------------------
    def _open(self, now: float) -> None:
        try:
            self._bus = can.Bus(
                interface=self.interface, channel=self.can_channel, bitrate=self.bitrate
            )
        except (can.CanError, OSError, ValueError) as exc:
            raise DeviceError(
                self.name, f"cannot open CAN {self.interface}:{self.can_channel}: {exc}"
            ) from exc
        self._opened_at = now
        self._now = now
        try:
            for node in self._nodes.values():
                node.dirty = False
                node.up = False
                node.last_heartbeat = None
                node.encoder = None
                node.axis_state = oc.AxisState.UNDEFINED
                node.axis_error = 0
                self._send(node.node_id, oc.Cmd.CLEAR_ERRORS, oc.encode_clear_errors())
                self._send(
                    node.node_id,
                    oc.Cmd.SET_CONTROLLER_MODE,
                    oc.encode_set_controller_mode(oc.ControlMode.VELOCITY, oc.InputMode.VEL_RAMP),
                )
                self._send(
                    node.node_id,
                    oc.Cmd.SET_AXIS_STATE,
                    oc.encode_set_axis_state(oc.AxisState.CLOSED_LOOP_CONTROL),
                )
                self._send(node.node_id, oc.Cmd.SET_INPUT_VEL, oc.encode_set_input_vel(0.0))
                node.next_refresh = now + self.refresh
        except DeviceError:
            self._shutdown()
            raise

    def _tick(self, now: float, dt: float) -> None:
        self._now = now
        caught_up = self._drain(now)
        self._check(now, stale=caught_up)
        for node in self._nodes.values():
            if node.dirty or now >= node.next_refresh - _EPS:
                self._send_vel(node, now)

    def _stop_motors(self) -> None:
        failed: DeviceError | None = None
        for node in self._nodes.values():
            try:
                self._send_vel(node, self._now, stop=True)
            except DeviceError as exc:
                failed = failed or exc
        if failed is not None:
            raise failed

    def _close(self) -> None:
        if self._bus is None:
            return
        for node in self._nodes.values():
            # best effort: the bus may be the thing that failed
            with contextlib.suppress(DeviceError):
                self._send(
                    node.node_id, oc.Cmd.SET_AXIS_STATE, oc.encode_set_axis_state(oc.AxisState.IDLE)
                )
            node.up = False
        self._shutdown()

    # -- internals ------------------------------------------------------------------------------
    def _shutdown(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            with contextlib.suppress(can.CanError, OSError):  # closing must always finish
                bus.shutdown()

    def _motor_changed(self, ch: MotorChannel) -> None:
        """Send the new velocity now; a failure surfaces from the next tick, not the request."""
        assert isinstance(ch, _Motor)
        node = self._nodes[ch.node_id]
        node.dirty = True
        if self._bus is None:
            return
        try:
            self._send_vel(node, self._now)
        except DeviceError as exc:
            self.failure = self.failure or exc

    def _send_vel(self, node: _Node, now: float, stop: bool = False) -> None:
        """Set_Input_Vel for the channel's duty (or 0 for a stop, which leaves the commanded
        value to the layers above)."""
        node.dirty = True  # stays set if the send fails, so the next tick retries
        vel = 0.0 if stop else node.channel.duty * self.max_vel
        self._send(node.node_id, oc.Cmd.SET_INPUT_VEL, oc.encode_set_input_vel(vel))
        node.dirty = False
        node.next_refresh = now + self.refresh

    def _send(self, node_id: int, cmd: int, data: bytes, remote: bool = False) -> None:
        if self._bus is None:
            raise DeviceError(self.name, "CAN bus is not open")
        msg = can.Message(
            arbitration_id=oc.arbitration_id(node_id, cmd),
            data=data,
            is_extended_id=False,
            is_remote_frame=remote,
            dlc=8 if remote else len(data),
        )
        try:
            self._bus.send(msg, timeout=0)
        except (can.CanError, OSError) as exc:
            raise DeviceError(
                self.name, f"CAN send of {oc.Cmd(cmd).name} failed: {exc}", f"node {node_id}"
            ) from exc
        self.stats["sent"] += 1

    def _drain(self, now: float) -> bool:
        """Handle received frames; False when MAX_DRAIN left some queued for the next tick."""
        bus = self._bus
        if bus is None:
            return True
        for _ in range(MAX_DRAIN):
            try:
                msg = bus.recv(timeout=0)
            except (can.CanError, OSError) as exc:
                raise DeviceError(self.name, f"CAN receive failed: {exc}") from exc
            if msg is None:
                return True
            self.stats["recv"] += 1
            self._handle(msg, now)
        return False

    def _handle(self, msg: can.Message, now: float) -> None:
        if msg.is_error_frame or msg.is_extended_id or msg.is_remote_frame:
            self.stats["ignored"] += 1
            return
        node_id, cmd = oc.split_id(msg.arbitration_id)
        node = self._nodes.get(node_id)
        if node is None:
            self.stats["ignored"] += 1
            return
        data = bytes(msg.data)
        try:
            if cmd == oc.Cmd.HEARTBEAT:
                hb = oc.decode_heartbeat(data)
                node.last_heartbeat = now
                node.axis_state = hb.axis_state
                node.axis_error = hb.axis_error
                if hb.axis_state == oc.AxisState.CLOSED_LOOP_CONTROL and hb.axis_error == 0:
                    node.up = True
            elif cmd == oc.Cmd.GET_ENCODER_ESTIMATES:
                node.encoder = oc.decode_encoder_estimates(data)
            elif cmd == oc.Cmd.GET_BUS_VOLTAGE:
                node.bus_voltage = oc.decode_bus_voltage(data)
            else:
                self.stats["ignored"] += 1
        except oc.CodecError:
            self.stats["bad"] += 1

    def _check(self, now: float, stale: bool = True) -> None:
        """Raise DeviceError for the first axis that cannot be trusted.

        `stale=False` skips the age checks: with frames still queued, a fresh heartbeat may
        be among them, and our own slowness must not look like a dead ODrive."""
        for node in self._nodes.values():
            if not node.up:
                if now - self._opened_at <= self.grace or not stale:
                    continue
                if node.last_heartbeat is None:
                    why = f"no heartbeat within {self.grace:g} s of open"
                else:
                    why = (f"did not reach CLOSED_LOOP_CONTROL within {self.grace:g} s of open "
                           f"(state {oc.state_name(node.axis_state)}, "
                           f"error {oc.error_names(node.axis_error)})")
                raise DeviceError(self.name, why, node.who)
            assert node.last_heartbeat is not None
            age = now - node.last_heartbeat
            if stale and age > self.heartbeat_timeout:
                raise DeviceError(
                    self.name,
                    f"heartbeat stale ({age:.3f} s old, timeout {self.heartbeat_timeout:g} s)",
                    node.who,
                )
            if node.axis_error:
                raise DeviceError(
                    self.name, f"axis error {oc.error_names(node.axis_error)}", node.who
                )
            if node.axis_state != oc.AxisState.CLOSED_LOOP_CONTROL:
                raise DeviceError(
                    self.name,
                    f"axis left CLOSED_LOOP_CONTROL (now {oc.state_name(node.axis_state)})",
                    node.who,
                )
