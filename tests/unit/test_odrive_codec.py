"""ODrive CAN Simple codec: exact bytes, validation, and a cross-check against ODrive's DBC.

tests/data/odrive-cansimple.dbc is a copy of odriverobotics/ODrive `tools/odrive-cansimple.dbc`
(MIT licence), the definition nobody on this project wrote.
"""

from __future__ import annotations

import functools
import math
import struct
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ramp.hal import odrive_codec as oc

cantools = pytest.importorskip("cantools")  # a dev-only dependency

HERE = Path(__file__).resolve().parent
DBC = HERE.parent / "data" / "odrive-cansimple.dbc"
#: Where CI's sibling checkout keeps the original; used only to check our copy is the same.
SHARED_DBC = HERE.parents[2] / "shared" / "reference" / "odrive-cansimple.dbc"


@functools.cache
def load_dbc() -> Any:
    return cantools.database.load_file(str(DBC))


@pytest.fixture
def db() -> Any:
    return load_dbc()


def f32(x: float) -> float:
    """x as it survives a round trip through an IEEE-754 single."""
    return float(struct.unpack("<f", struct.pack("<f", x))[0])


finite_f32 = st.floats(allow_nan=False, allow_infinity=False, width=32)


# -- ids ------------------------------------------------------------------------------------------
def test_arbitration_id_is_node_shifted_by_five_or_command() -> None:
    assert oc.arbitration_id(3, oc.Cmd.SET_INPUT_VEL) == 0x6D
    assert oc.arbitration_id(0, oc.Cmd.HEARTBEAT) == 0x001
    assert oc.arbitration_id(63, oc.Cmd.CLEAR_ERRORS) == 0x7F8
    assert oc.arbitration_id(0x10, oc.Cmd.HEARTBEAT) == 0x201  # the CANopen-reserved example


def test_split_id_inverts_arbitration_id() -> None:
    for node in (0, 1, 17, 63):
        for cmd in oc.Cmd:
            assert oc.split_id(oc.arbitration_id(node, cmd)) == (node, cmd)
    with pytest.raises(oc.CodecError):
        oc.split_id(0x800)


@pytest.mark.parametrize("bad", [-1, 64, 100, True, 1.0, "3"])
def test_node_id_outside_0_63_is_refused(bad: object) -> None:
    with pytest.raises(oc.CodecError):
        oc.arbitration_id(bad, oc.Cmd.HEARTBEAT)  # type: ignore[arg-type]


# -- exact bytes ----------------------------------------------------------------------------------
def test_set_input_vel_bytes() -> None:
    assert oc.encode_set_input_vel(2.5) == bytes.fromhex("0000204000000000")
    assert oc.encode_set_input_vel(-1.0, 0.5) == bytes.fromhex("000080bf0000003f")
    assert oc.decode_set_input_vel(bytes.fromhex("000080bf0000003f")) == (-1.0, 0.5)


def test_heartbeat_bytes_0_5_layout() -> None:
    hb = oc.Heartbeat(axis_error=0x40, axis_state=oc.AxisState.CLOSED_LOOP_CONTROL)
    assert oc.encode_heartbeat(hb) == bytes.fromhex("4000000008000000")
    flagged = oc.Heartbeat(0x1, 1, motor_error=True, encoder_error=True,
                           controller_error=True, trajectory_done=True)
    data = oc.encode_heartbeat(flagged)
    assert data == bytes.fromhex("0100000001010181")
    assert oc.decode_heartbeat(data) == flagged


def test_command_bytes() -> None:
    assert oc.encode_set_axis_state(oc.AxisState.CLOSED_LOOP_CONTROL) == bytes.fromhex(
        "0800000000000000")
    assert oc.decode_set_axis_state(bytes.fromhex("0100000000000000")) == oc.AxisState.IDLE
    assert oc.encode_set_controller_mode(oc.ControlMode.VELOCITY, oc.InputMode.VEL_RAMP) == (
        bytes.fromhex("0200000002000000"))
    assert oc.decode_set_controller_mode(bytes.fromhex("0300000005000000")) == (3, 5)
    assert oc.encode_encoder_estimates(1.0, -2.0) == bytes.fromhex("0000803f000000c0")
    assert oc.decode_encoder_estimates(bytes.fromhex("0000803f000000c0")) == (1.0, -2.0)
    assert oc.encode_set_limits(20.0, 10.0) == bytes.fromhex("0000a04100002041")
    assert oc.encode_bus_voltage(24.0) == bytes.fromhex("0000c04100000000")
    assert oc.decode_bus_voltage(bytes.fromhex("0000c041")) == 24.0
    assert oc.encode_estop() == b""
    assert oc.encode_clear_errors() == b""


def test_enum_values_of_firmware_0_5() -> None:
    assert (oc.AxisState.IDLE, oc.AxisState.FULL_CALIBRATION_SEQUENCE,
            oc.AxisState.CLOSED_LOOP_CONTROL) == (1, 3, 8)
    assert (oc.ControlMode.VOLTAGE, oc.ControlMode.TORQUE, oc.ControlMode.VELOCITY,
            oc.ControlMode.POSITION) == (0, 1, 2, 3)
    assert (oc.InputMode.INACTIVE, oc.InputMode.PASSTHROUGH, oc.InputMode.VEL_RAMP,
            oc.InputMode.POS_FILTER, oc.InputMode.TRAP_TRAJ) == (0, 1, 2, 3, 5)


def test_error_and_state_names_for_messages() -> None:
    assert oc.error_names(0x41) == "0x00000041 (INVALID_STATE|MOTOR_FAILED)"
    assert oc.error_names(0x40000000) == "0x40000000 (0x40000000)"
    assert oc.state_name(8) == "CLOSED_LOOP_CONTROL"
    assert oc.state_name(99) == "99"


# -- validation -----------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e39, True, "1"])
def test_non_finite_or_unpackable_floats_are_refused(bad: object) -> None:
    with pytest.raises(oc.CodecError):
        oc.encode_set_input_vel(bad)  # type: ignore[arg-type]
    with pytest.raises(oc.CodecError):
        oc.encode_set_input_vel(0.0, bad)  # type: ignore[arg-type]
    with pytest.raises(oc.CodecError):
        oc.encode_set_limits(bad, 1.0)  # type: ignore[arg-type]


def test_bad_ints_are_refused() -> None:
    with pytest.raises(oc.CodecError):
        oc.encode_set_axis_state(-1)
    with pytest.raises(oc.CodecError):
        oc.encode_set_controller_mode(2**31, 0)
    with pytest.raises(oc.CodecError):
        oc.encode_heartbeat(oc.Heartbeat(axis_error=-1, axis_state=1))
    with pytest.raises(oc.CodecError):
        oc.encode_heartbeat(oc.Heartbeat(axis_error=0, axis_state=256))


@pytest.mark.parametrize("decode", [
    oc.decode_heartbeat, oc.decode_encoder_estimates, oc.decode_set_input_vel,
    oc.decode_set_controller_mode, oc.decode_set_limits, oc.decode_set_axis_state,
    oc.decode_bus_voltage,
])
def test_short_payloads_are_codec_errors(decode: object) -> None:
    with pytest.raises(oc.CodecError, match="needs"):
        decode(b"\x00\x00\x00")  # type: ignore[operator]


# -- cross-check against ODrive's DBC -------------------------------------------------------------
def test_dbc_copy_matches_shared_reference_when_present() -> None:
    if not SHARED_DBC.exists():
        pytest.skip("no sibling shared/ checkout")
    assert DBC.read_bytes() == SHARED_DBC.read_bytes()


def test_our_frames_decode_with_the_dbc(db: Any) -> None:
    def dbc(node: int, cmd: oc.Cmd, data: bytes) -> dict[str, float]:
        arb = oc.arbitration_id(node, cmd)
        decoded: dict[str, float] = db.decode_message(arb & 0x1F, data)
        return decoded

    assert dbc(5, oc.Cmd.SET_INPUT_VEL, oc.encode_set_input_vel(2.5, -0.25)) == {
        "Input_Vel": 2.5, "Input_Torque_FF": -0.25}
    assert dbc(5, oc.Cmd.SET_AXIS_STATE, oc.encode_set_axis_state(8)) == {
        "Axis_Requested_State": 8}
    assert dbc(5, oc.Cmd.SET_CONTROLLER_MODE, oc.encode_set_controller_mode(2, 2)) == {
        "Control_Mode": 2, "Input_Mode": 2}
    assert dbc(5, oc.Cmd.SET_LIMITS, oc.encode_set_limits(20.0, 10.0)) == {
        "Velocity_Limit": 20.0, "Current_Limit": 10.0}
    assert dbc(5, oc.Cmd.HEARTBEAT, oc.encode_heartbeat(oc.Heartbeat(0x800, 1))) == {
        "Axis_Error": 0x800, "Axis_State": 1}  # flags zero, so the DBC's u32 state agrees
    assert dbc(5, oc.Cmd.GET_ENCODER_ESTIMATES, oc.encode_encoder_estimates(12.5, -3.0)) == {
        "Pos_Estimate": 12.5, "Vel_Estimate": -3.0}
    assert dbc(5, oc.Cmd.GET_BUS_VOLTAGE, oc.encode_bus_voltage(24.5)) == {"Vbus_Voltage": 24.5}


def test_dbc_frames_decode_with_our_codec(db: Any) -> None:
    def enc(name: str, values: dict[str, float]) -> bytes:
        msg = db.get_message_by_name(name)
        data: bytes = msg.encode(values)
        return data

    assert oc.decode_set_input_vel(enc("Set_Input_Vel", {"Input_Vel": -7.75,
                                                         "Input_Torque_FF": 0.0})) == (-7.75, 0.0)
    assert oc.decode_set_axis_state(enc("Set_Axis_State", {"Axis_Requested_State": 8})) == 8
    assert oc.decode_set_controller_mode(
        enc("Set_Controller_Mode", {"Control_Mode": 2, "Input_Mode": 2})) == (2, 2)
    assert oc.decode_set_limits(
        enc("Set_Limits", {"Velocity_Limit": 15.0, "Current_Limit": 30.0})) == (15.0, 30.0)
    hb = oc.decode_heartbeat(enc("Heartbeat", {"Axis_Error": 0x4000, "Axis_State": 8}))
    assert hb == oc.Heartbeat(0x4000, 8)
    assert oc.decode_encoder_estimates(
        enc("Get_Encoder_Estimates", {"Pos_Estimate": -1.5, "Vel_Estimate": 4.0})) == (-1.5, 4.0)
    assert oc.decode_bus_voltage(enc("Get_Vbus_Voltage", {"Vbus_Voltage": 48.0})) == 48.0


@given(vel=finite_f32, torque=finite_f32)
def test_set_input_vel_agrees_with_dbc_for_any_f32(vel: float, torque: float) -> None:
    db = load_dbc()
    msg = db.get_message_by_name("Set_Input_Vel")
    ours = oc.encode_set_input_vel(vel, torque)
    assert msg.encode({"Input_Vel": vel, "Input_Torque_FF": torque}) == ours
    decoded = db.decode_message(0x0D, ours)
    assert decoded["Input_Vel"] == f32(vel)
    assert oc.decode_set_input_vel(ours) == (f32(vel), f32(torque))
