"""ODrive (firmware 0.5.x) axes speaking CAN Simple on a python-can `virtual` bus.

The emulator opens its own bus on the driver's channel name, so the two share only frames.
It packs and unpacks frames itself (not with `ramp.hal.odrive_codec`), so a codec mistake
shows up as a driver test failure instead of agreeing with itself.

Behaviour modelled on firmware 0.5.x:
- each axis boots IDLE in POSITION/PASSTHROUGH mode (the firmware defaults);
- Set_Axis_State(CLOSED_LOOP_CONTROL) enters closed loop only when the axis has no error;
  Set_Axis_State(IDLE) leaves it; other requested states are not modelled (ignored);
- Set_Input_Vel is ignored outside closed loop; the velocity follows it in VELOCITY mode,
  ramped at `vel_ramp_rate` turns/s^2 when the input mode is VEL_RAMP and a rate is given,
  clamped to the Set_Limits velocity limit;
- Clear_Errors clears the axis error; Estop sets ESTOP_REQUESTED and drops to IDLE;
- an optional watchdog (`watchdog_timeout`, like `axis.config.enable_watchdog`) is fed by
  every frame addressed to the axis and, when it expires in closed loop, sets
  WATCHDOG_TIMER_EXPIRED and drops to IDLE;
- Heartbeat every 100 ms and Get_Encoder_Estimates every 10 ms (position integrated from
  velocity); RTR requests for encoder estimates and bus voltage are answered at once.

No threads: everything happens in `tick(now)`, which the test or the simulator calls.
"""

from __future__ import annotations

import logging
import math
import struct
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import can

HEARTBEAT_PERIOD = 0.1
ENCODER_PERIOD = 0.01
#: Frames `rx_log` keeps, newest last: a minute of a four-axis drive refreshed at 20 Hz is
#: about 4,800, and a simulated RMC run must not grow without bound.
RX_LOG_FRAMES = 10_000
_EPS = 1e-9  # float slack so a tick landing on a due time is not one slot late

# CAN Simple command ids and 0.5.x enum values, written out independently of the driver.
HEARTBEAT, ESTOP, SET_AXIS_STATE, GET_ENCODER_ESTIMATES = 0x01, 0x02, 0x07, 0x09
SET_CONTROLLER_MODE, SET_INPUT_VEL, SET_LIMITS = 0x0B, 0x0D, 0x0F
GET_VBUS_VOLTAGE, CLEAR_ERRORS = 0x17, 0x18
IDLE, CLOSED_LOOP_CONTROL = 1, 8
VELOCITY_CONTROL, POSITION_CONTROL = 2, 3
PASSTHROUGH, VEL_RAMP = 1, 2
ERROR_MOTOR_FAILED = 0x40
ERROR_ENCODER_FAILED = 0x100
ERROR_CONTROLLER_FAILED = 0x200
ERROR_WATCHDOG_TIMER_EXPIRED = 0x800
ERROR_ESTOP_REQUESTED = 0x4000


@dataclass
class AxisModel:
    """One emulated axis; tests read these fields directly."""

    node_id: int
    state: int = IDLE
    error: int = 0
    control_mode: int = POSITION_CONTROL
    input_mode: int = PASSTHROUGH
    input_vel: float = 0.0
    vel: float = 0.0
    pos: float = 0.0
    vel_limit: float = math.inf
    current_limit: float = 10.0
    last_fed: float | None = None
    silent: bool = False


class ODriveEmulator:
    """ODrive axes `node_ids` on the virtual CAN channel `channel`.

    `on_velocity(node_id, turns_per_s)` is called whenever an axis's velocity changes, so a
    physics model can turn the wheel; the emulator does not know the driver's `max_vel`.
    """

    def __init__(
        self,
        channel: str,
        node_ids: Iterable[int],
        on_velocity: Callable[[int, float], None] | None = None,
        *,
        vel_ramp_rate: float | None = None,
        watchdog_timeout: float | None = None,
        vbus: float = 24.0,
    ) -> None:
        self.axes: dict[int, AxisModel] = {}
        for n in node_ids:
            if not 0 <= n <= 63:
                raise ValueError(f"node id {n} is outside 0-63")
            self.axes[n] = AxisModel(n)
        self.on_velocity = on_velocity
        self.vel_ramp_rate = vel_ramp_rate
        self.watchdog_timeout = watchdog_timeout
        self.vbus = vbus
        #: The frames received lately (at most RX_LOG_FRAMES), with the `now` of the tick that
        #: read each (for tests).
        self.rx_log: deque[tuple[float, can.Message]] = deque(maxlen=RX_LOG_FRAMES)
        self._last_now: float | None = None
        self._next_heartbeat = 0.0
        self._next_encoder = 0.0
        self._bus: can.BusABC | None = can.Bus(interface="virtual", channel=channel)

    # -- fault injection ------------------------------------------------------------------------
    def fail(self, node_id: int, error: int = ERROR_MOTOR_FAILED) -> None:
        """Inject an axis error: the axis drops to IDLE and stops, as the firmware does."""
        axis = self.axes[node_id]
        axis.error |= error
        self._to_idle(axis)

    def silence(self, node_id: int | None = None) -> None:
        """Cable pulled: the axis (or all) neither sends nor hears frames."""
        for axis in self._pick(node_id):
            axis.silent = True

    def resume(self, node_id: int | None = None) -> None:
        for axis in self._pick(node_id):
            axis.silent = False

    def _pick(self, node_id: int | None) -> list[AxisModel]:
        return list(self.axes.values()) if node_id is None else [self.axes[node_id]]

    # -- running --------------------------------------------------------------------------------
    def tick(self, now: float) -> None:
        """Read every pending frame, move the axes to `now`, send what is due."""
        if self._bus is None:
            return
        dt = 0.0 if self._last_now is None else max(0.0, now - self._last_now)
        if self._last_now is None:
            self._next_heartbeat = now
            self._next_encoder = now
        self._last_now = now
        while True:
            msg = self._bus.recv(timeout=0)
            if msg is None:
                break
            self.rx_log.append((now, msg))
            self._handle(msg, now)
        for axis in self.axes.values():
            self._step(axis, now, dt)
        if now >= self._next_encoder - _EPS:
            for axis in self.axes.values():
                self._send_encoder(axis)
            self._next_encoder = _next(self._next_encoder, ENCODER_PERIOD, now)
        if now >= self._next_heartbeat - _EPS:
            for axis in self.axes.values():
                self._send_heartbeat(axis)
            self._next_heartbeat = _next(self._next_heartbeat, HEARTBEAT_PERIOD, now)

    def close(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            bus.shutdown()

    def __enter__(self) -> ODriveEmulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- frames in ------------------------------------------------------------------------------
    def _handle(self, msg: can.Message, now: float) -> None:
        if msg.is_extended_id or msg.is_error_frame:
            return
        node_id, cmd = msg.arbitration_id >> 5, msg.arbitration_id & 0x1F
        axis = self.axes.get(node_id)
        if axis is None or axis.silent:
            return
        axis.last_fed = now
        data = bytes(msg.data)
        if msg.is_remote_frame:
            if cmd == GET_ENCODER_ESTIMATES:
                self._send_encoder(axis)
            elif cmd == GET_VBUS_VOLTAGE:
                self._send(axis, GET_VBUS_VOLTAGE, struct.pack("<f4x", self.vbus))
            return
        if cmd == ESTOP:
            axis.error |= ERROR_ESTOP_REQUESTED
            self._to_idle(axis)
        elif cmd == SET_AXIS_STATE and len(data) >= 4:
            requested = struct.unpack_from("<I", data)[0]
            if requested == CLOSED_LOOP_CONTROL and axis.error == 0:
                axis.state = CLOSED_LOOP_CONTROL
                axis.input_vel = 0.0
            elif requested == IDLE:
                self._to_idle(axis)
        elif cmd == SET_CONTROLLER_MODE and len(data) >= 8:
            axis.control_mode, axis.input_mode = struct.unpack_from("<ii", data)
        elif cmd == SET_INPUT_VEL and len(data) >= 8:
            vel, _torque_ff = struct.unpack_from("<ff", data)
            if axis.state == CLOSED_LOOP_CONTROL and math.isfinite(vel):
                axis.input_vel = vel
        elif cmd == SET_LIMITS and len(data) >= 8:
            axis.vel_limit, axis.current_limit = struct.unpack_from("<ff", data)
        elif cmd == CLEAR_ERRORS:
            axis.error = 0

    # -- physics --------------------------------------------------------------------------------
    def _step(self, axis: AxisModel, now: float, dt: float) -> None:
        if (
            self.watchdog_timeout is not None
            and axis.state == CLOSED_LOOP_CONTROL
            and axis.last_fed is not None
            and now - axis.last_fed > self.watchdog_timeout
        ):
            axis.error |= ERROR_WATCHDOG_TIMER_EXPIRED
            self._to_idle(axis)
        target = 0.0
        if axis.state == CLOSED_LOOP_CONTROL and axis.control_mode == VELOCITY_CONTROL:
            target = max(-axis.vel_limit, min(axis.vel_limit, axis.input_vel))
        vel = target
        if (
            axis.state == CLOSED_LOOP_CONTROL
            and axis.input_mode == VEL_RAMP
            and self.vel_ramp_rate is not None
        ):
            step = self.vel_ramp_rate * dt
            vel = axis.vel + max(-step, min(step, target - axis.vel))
        axis.pos += (axis.vel + vel) / 2.0 * dt
        self._set_vel(axis, vel)

    def _to_idle(self, axis: AxisModel) -> None:
        axis.state = IDLE
        axis.input_vel = 0.0
        self._set_vel(axis, 0.0)

    def _set_vel(self, axis: AxisModel, vel: float) -> None:
        if vel != axis.vel:
            axis.vel = vel
            if self.on_velocity is not None:
                self.on_velocity(axis.node_id, vel)

    # -- frames out -----------------------------------------------------------------------------
    def _send_heartbeat(self, axis: AxisModel) -> None:
        flags_motor = 1 if axis.error & ERROR_MOTOR_FAILED else 0
        flags_encoder = 1 if axis.error & ERROR_ENCODER_FAILED else 0
        flags_controller = 1 if axis.error & ERROR_CONTROLLER_FAILED else 0
        data = struct.pack(
            "<IBBBB", axis.error, axis.state, flags_motor, flags_encoder, flags_controller
        )
        self._send(axis, HEARTBEAT, data)

    def _send_encoder(self, axis: AxisModel) -> None:
        self._send(axis, GET_ENCODER_ESTIMATES, struct.pack("<ff", axis.pos, axis.vel))

    def _send(self, axis: AxisModel, cmd: int, data: bytes) -> None:
        if axis.silent or self._bus is None:
            return
        self._bus.send(
            can.Message(arbitration_id=axis.node_id << 5 | cmd, data=data, is_extended_id=False)
        )


def _next(due: float, period: float, now: float) -> float:
    """The next due time on the period grid; skips missed slots instead of bursting."""
    due += period
    if due <= now + _EPS:
        due = now + period
    return due


def emulated_bus(ctx: Any, bc: Any) -> dict[str, Any]:
    """`ramp.emulators` entry `bus.can`: ODrive emulators on python-can's virtual bus, one per
    motor's node id, moving the world's motors; the real driver talks CAN frames to them."""
    labels = ctx.motor_labels(bc.name, "node_id")
    max_vel = float(bc.params["max_vel"])
    world = ctx.signals

    def on_velocity(node: int, turns_per_s: float) -> None:
        label = labels.get(node)
        if label is not None:
            world.set_motor(label, max(-1.0, min(1.0, turns_per_s / max_vel)))

    channel = f"ramp-sim-{id(ctx):x}-{bc.name}"
    emulator = ODriveEmulator(channel, sorted(labels), on_velocity=on_velocity)
    ctx.add_device(emulator)
    ctx.add_service(emulator.tick)
    ctx.add_bus_emulator(bc.name, emulator)
    logging.getLogger("ramp.sim").info("bus %s: ODrive emulators (nodes %s) on virtual CAN",
                                       bc.name, ",".join(map(str, sorted(labels))))
    return {"interface": "virtual", "channel": channel}
