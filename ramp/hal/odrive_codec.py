"""ODrive CAN Simple frames as pure bytes (sans-IO), firmware 0.5.x.

We target the ODrive 0.5.x generation (ODrive v3.x boards), the one ODrive's own
`odrive-cansimple.dbc` describes. In 0.5.x the heartbeat carries the axis state as a u8 at
byte 4 and three error flags plus trajectory-done in bytes 5-7; 0.6.x (Pro/S1) reuses
those bytes differently, so a driver must know which one it talks to.

Frames use 11-bit ids `node_id << 5 | cmd`, node 0-63, little-endian payloads, IEEE-754
floats. Every function here takes and returns plain values and `bytes`, so the driver, the
emulator and the tests share one definition and none of them needs a CAN bus to check it.
Encoders validate (a NaN velocity must never reach a motor controller); decoders check length
and raise `CodecError` (a ValueError) on a short payload.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag

#: Largest finite value an IEEE-754 single holds; bigger floats cannot be packed.
F32_MAX = 3.4028234663852886e38
NODE_MIN, NODE_MAX = 0, 63


class CodecError(ValueError):
    """A value that cannot be encoded, or bytes that are not the frame they claim to be."""


class Cmd(IntEnum):
    """CAN Simple command ids (the low 5 bits of the arbitration id)."""

    HEARTBEAT = 0x001
    ESTOP = 0x002
    SET_AXIS_STATE = 0x007
    GET_ENCODER_ESTIMATES = 0x009
    SET_CONTROLLER_MODE = 0x00B
    SET_INPUT_VEL = 0x00D
    SET_LIMITS = 0x00F
    GET_BUS_VOLTAGE = 0x017  # "Get_Vbus_Voltage" in the 0.5.x DBC
    CLEAR_ERRORS = 0x018


class AxisState(IntEnum):
    """`Axis.AxisState` of firmware 0.5.x."""

    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8
    LOCKIN_SPIN = 9
    ENCODER_DIR_FIND = 10
    HOMING = 11
    ENCODER_HALL_POLARITY_CALIBRATION = 12
    ENCODER_HALL_PHASE_CALIBRATION = 13


class ControlMode(IntEnum):
    """`Controller.ControlMode` of firmware 0.5.x."""

    VOLTAGE = 0
    TORQUE = 1
    VELOCITY = 2
    POSITION = 3


class InputMode(IntEnum):
    """`Controller.InputMode` of firmware 0.5.x."""

    INACTIVE = 0
    PASSTHROUGH = 1
    VEL_RAMP = 2
    POS_FILTER = 3
    MIX_CHANNELS = 4
    TRAP_TRAJ = 5
    TORQUE_RAMP = 6
    MIRROR = 7
    TUNING = 8


class AxisError(IntFlag):
    """`Axis.Error` bits of firmware 0.5.x, for readable fault messages."""

    NONE = 0
    INVALID_STATE = 0x1
    MOTOR_FAILED = 0x40
    SENSORLESS_ESTIMATOR_FAILED = 0x80
    ENCODER_FAILED = 0x100
    CONTROLLER_FAILED = 0x200
    WATCHDOG_TIMER_EXPIRED = 0x800
    MIN_ENDSTOP_PRESSED = 0x1000
    MAX_ENDSTOP_PRESSED = 0x2000
    ESTOP_REQUESTED = 0x4000
    HOMING_WITHOUT_ENDSTOP = 0x20000
    OVER_TEMP = 0x40000
    UNKNOWN_POSITION = 0x80000


def state_name(state: int) -> str:
    """`CLOSED_LOOP_CONTROL`, or the number for a state this firmware list lacks."""
    try:
        return AxisState(state).name
    except ValueError:
        return str(state)


def error_names(error: int) -> str:
    """`0x00000041 (INVALID_STATE|MOTOR_FAILED)`: the raw word always, names where known."""
    names = [e.name for e in AxisError if e.value and error & e.value and e.name]
    unknown = error & ~sum(e.value for e in AxisError)
    if unknown:
        names.append(f"0x{unknown:x}")
    return f"0x{error:08x}" + (f" ({'|'.join(names)})" if names else "")


# -- ids ------------------------------------------------------------------------------------------
def check_node(node_id: int) -> int:
    if isinstance(node_id, bool) or not isinstance(node_id, int):
        raise CodecError(f"node id must be an int, got {node_id!r}")
    if not NODE_MIN <= node_id <= NODE_MAX:
        raise CodecError(f"node id {node_id} is outside {NODE_MIN}-{NODE_MAX}")
    return node_id


def arbitration_id(node_id: int, cmd: int) -> int:
    """The 11-bit CAN id of `cmd` for `node_id`."""
    check_node(node_id)
    if not 0 <= int(cmd) <= 0x1F:
        raise CodecError(f"command id {cmd} is outside 0-31")
    return node_id << 5 | int(cmd)


def split_id(arb_id: int) -> tuple[int, int]:
    """(node_id, cmd) of an 11-bit CAN id."""
    if not 0 <= arb_id <= 0x7FF:
        raise CodecError(f"0x{arb_id:x} is not an 11-bit CAN id")
    return arb_id >> 5, arb_id & 0x1F


# -- helpers --------------------------------------------------------------------------------------
def _f32(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise CodecError(f"{name} must be a number, got {value!r}")
    if not math.isfinite(value) or abs(value) > F32_MAX:
        raise CodecError(f"{name} must be a finite 32-bit float, got {value!r}")
    return float(value)


def _u32(name: str, value: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFFFFFF:
        raise CodecError(f"{name} must be an unsigned 32-bit int, got {value!r}")
    return value


def _i32(name: str, value: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not -(2**31) <= value < 2**31:
        raise CodecError(f"{name} must be a signed 32-bit int, got {value!r}")
    return value


def _need(data: bytes, n: int, what: str) -> None:
    if len(data) < n:
        raise CodecError(f"{what} needs {n} bytes, got {len(data)}")


# -- Heartbeat (0x001), axis -> host every 100 ms -------------------------------------------------
@dataclass(frozen=True)
class Heartbeat:
    """A 0.5.x heartbeat: axis error word, current state and the error summary flags."""

    axis_error: int
    axis_state: int
    motor_error: bool = False
    encoder_error: bool = False
    controller_error: bool = False
    trajectory_done: bool = False


def encode_heartbeat(hb: Heartbeat) -> bytes:
    """u32 axis_error, u8 axis_state, then flag bits 5.0 / 6.0 / 7.0 and 7.7."""
    state = hb.axis_state
    if isinstance(state, bool) or not isinstance(state, int) or not 0 <= state <= 0xFF:
        raise CodecError(f"axis_state must be a u8, got {state!r}")
    b7 = (0x01 if hb.controller_error else 0) | (0x80 if hb.trajectory_done else 0)
    return struct.pack(
        "<IBBBB", _u32("axis_error", hb.axis_error), state,
        1 if hb.motor_error else 0, 1 if hb.encoder_error else 0, b7,
    )


def decode_heartbeat(data: bytes) -> Heartbeat:
    _need(data, 8, "Heartbeat")
    err, state, b5, b6, b7 = struct.unpack_from("<IBBBB", data)
    return Heartbeat(err, state, bool(b5 & 1), bool(b6 & 1), bool(b7 & 1), bool(b7 & 0x80))


# -- Estop (0x002) and Clear_Errors (0x018): no payload --------------------------------------------
def encode_estop() -> bytes:
    return b""


def encode_clear_errors() -> bytes:
    return b""


# -- Set_Axis_State (0x007) -----------------------------------------------------------------------
def encode_set_axis_state(state: int) -> bytes:
    """u32 requested state, padded to the 8 bytes the DBC declares."""
    return struct.pack("<I4x", _u32("requested state", int(state)))


def decode_set_axis_state(data: bytes) -> int:
    _need(data, 4, "Set_Axis_State")
    value: int = struct.unpack_from("<I", data)[0]
    return value


# -- Get_Encoder_Estimates (0x009), axis -> host every 10 ms --------------------------------------
def encode_encoder_estimates(pos: float, vel: float) -> bytes:
    """f32 position (turns), f32 velocity (turns/s)."""
    return struct.pack("<ff", _f32("pos", pos), _f32("vel", vel))


def decode_encoder_estimates(data: bytes) -> tuple[float, float]:
    _need(data, 8, "Get_Encoder_Estimates")
    pos, vel = struct.unpack_from("<ff", data)
    return pos, vel


# -- Set_Controller_Mode (0x00B) ------------------------------------------------------------------
def encode_set_controller_mode(control_mode: int, input_mode: int) -> bytes:
    return struct.pack(
        "<ii", _i32("control_mode", int(control_mode)), _i32("input_mode", int(input_mode))
    )


def decode_set_controller_mode(data: bytes) -> tuple[int, int]:
    _need(data, 8, "Set_Controller_Mode")
    control, inp = struct.unpack_from("<ii", data)
    return control, inp


# -- Set_Input_Vel (0x00D) ------------------------------------------------------------------------
def encode_set_input_vel(vel: float, torque_ff: float = 0.0) -> bytes:
    """f32 velocity (turns/s), f32 torque feed-forward (Nm)."""
    return struct.pack("<ff", _f32("vel", vel), _f32("torque_ff", torque_ff))


def decode_set_input_vel(data: bytes) -> tuple[float, float]:
    _need(data, 8, "Set_Input_Vel")
    vel, torque = struct.unpack_from("<ff", data)
    return vel, torque


# -- Set_Limits (0x00F) ---------------------------------------------------------------------------
def encode_set_limits(vel_limit: float, current_limit: float) -> bytes:
    """f32 velocity limit (turns/s), f32 current limit (A)."""
    return struct.pack("<ff", _f32("vel_limit", vel_limit), _f32("current_limit", current_limit))


def decode_set_limits(data: bytes) -> tuple[float, float]:
    _need(data, 8, "Set_Limits")
    vel, cur = struct.unpack_from("<ff", data)
    return vel, cur


# -- Get_Bus_Voltage (0x017): host sends an RTR frame, axis answers f32 volts ---------------------
def encode_bus_voltage(volts: float) -> bytes:
    """f32 DC bus voltage; the DBC declares 8 bytes, so the rest is zero."""
    return struct.pack("<f4x", _f32("volts", volts))


def decode_bus_voltage(data: bytes) -> float:
    _need(data, 4, "Get_Bus_Voltage")
    volts: float = struct.unpack_from("<f", data)[0]
    return volts
