"""The `can` driver against the ODrive emulator on python-can's virtual bus, in virtual time.

A third bus on the same channel (the sniffer) sees every frame the driver puts on the wire;
frames are checked as bytes and decoded with ODrive's own DBC (tests/data/odrive-cansimple.dbc,
a copy of odriverobotics/ODrive `tools/odrive-cansimple.dbc`, MIT licence).
"""

from __future__ import annotations

import functools
import itertools
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest

from firmware_like.odrive import ODriveEmulator
from ramp.errors import ConfigError, DeviceError
from ramp.hal import driver_class
from ramp.hal.odrive import ODriveBus

DBC = Path(__file__).resolve().parent.parent / "data" / "odrive-cansimple.dbc"
DT = 0.01
NODES = {"base.lf_wheel": 1, "base.rf_wheel": 2}
_channels = itertools.count()


@functools.cache
def dbc() -> Any:
    cantools = pytest.importorskip("cantools")
    return cantools.database.load_file(str(DBC))


class Rig:
    """Driver, emulator and sniffer on one fresh virtual channel; `now` moves only in `run`."""

    def __init__(self, emu_nodes: list[int] | None = None, **params: Any) -> None:
        self.channel = f"odrive-test-{next(_channels)}"
        self.velocities: list[tuple[int, float]] = []
        nodes = NODES.values() if emu_nodes is None else emu_nodes
        self.emu = ODriveEmulator(self.channel, nodes,
                                  on_velocity=lambda n, v: self.velocities.append((n, v)),
                                  **params.pop("emu", {}))
        self.sniffer = can.Bus(interface="virtual", channel=self.channel)
        self.drv = ODriveBus("base_can", {"channel": self.channel, **params})
        self.motors = {label: self.drv.channel("motor", label, {"node_id": n})
                       for label, n in NODES.items()}
        self.now = 0.0

    def open(self) -> None:
        self.drv.open(self.now)

    def step(self, emu: bool = True) -> None:
        self.now = round(self.now + DT, 9)
        self.drv.tick(self.now, DT)
        if emu:
            self.emu.tick(self.now)

    def run(self, seconds: float, emu: bool = True) -> None:
        for _ in range(round(seconds / DT)):
            self.step(emu)

    def start(self) -> None:
        """Open and run until every axis reports closed loop."""
        self.open()
        self.emu.tick(self.now)
        self.run(0.3)
        assert self.drv.ready()
        self.sniffed()

    def sniffed(self) -> list[can.Message]:
        """Frames the driver sent since the last call (the emulator's are filtered out)."""
        out = []
        while (msg := self.sniffer.recv(timeout=0)) is not None:
            if msg.is_remote_frame or msg.arbitration_id & 0x1F not in (0x01, 0x09, 0x17):
                out.append(msg)
        return out

    def close(self) -> None:
        self.drv.close()
        self.emu.close()
        self.sniffer.shutdown()


@pytest.fixture
def rig() -> Iterator[Rig]:
    r = Rig()
    yield r
    r.close()


def vel_frames(msgs: list[can.Message]) -> list[tuple[int, float]]:
    """(node, velocity) of every Set_Input_Vel, decoded with the DBC."""
    out = []
    for m in msgs:
        if m.arbitration_id & 0x1F == 0x0D:
            assert m.dlc == 8 and not m.is_extended_id
            decoded = dbc().decode_message(0x0D, bytes(m.data))
            assert decoded["Input_Torque_FF"] == 0.0
            out.append((m.arbitration_id >> 5, decoded["Input_Vel"]))
    return out


# -- start-up -------------------------------------------------------------------------------------
def test_open_sends_the_start_up_sequence_per_axis(rig: Rig) -> None:
    rig.open()
    sent = rig.sniffed()
    assert [(m.arbitration_id, bytes(m.data)) for m in sent] == [
        (0x038, b""),                                    # node 1 Clear_Errors
        (0x02B, bytes.fromhex("0200000002000000")),      # Set_Controller_Mode VELOCITY, VEL_RAMP
        (0x027, bytes.fromhex("0800000000000000")),      # Set_Axis_State CLOSED_LOOP_CONTROL
        (0x02D, bytes(8)),                               # Set_Input_Vel 0
        (0x058, b""),
        (0x04B, bytes.fromhex("0200000002000000")),
        (0x047, bytes.fromhex("0800000000000000")),
        (0x04D, bytes(8)),
    ]
    db = dbc()
    assert db.decode_message(0x0B, bytes(sent[1].data)) == {"Control_Mode": 2, "Input_Mode": 2}
    assert db.decode_message(0x07, bytes(sent[2].data)) == {"Axis_Requested_State": 8}
    assert rig.drv.stats["sent"] == 8


def test_start_up_reaches_closed_loop(rig: Rig) -> None:
    assert all(a.state == 1 for a in rig.emu.axes.values())  # firmware boots IDLE
    rig.open()
    assert not rig.drv.ready()
    rig.emu.tick(rig.now)
    for axis in rig.emu.axes.values():
        assert (axis.state, axis.control_mode, axis.input_mode) == (8, 2, 2)
    rig.run(0.3)
    assert rig.drv.ready()
    assert rig.drv.axis(1) == (8, 0)
    assert rig.drv.encoder(2) == (0.0, 0.0)
    assert rig.drv.stats["recv"] > 0


def test_open_starts_from_rest_even_if_a_duty_was_set_while_closed(rig: Rig) -> None:
    rig.motors["base.lf_wheel"].set_duty(0.7)
    assert rig.sniffed() == []  # nothing goes out while closed
    rig.open()
    assert rig.motors["base.lf_wheel"].duty == 0.0
    assert vel_frames(rig.sniffed()) == [(1, 0.0), (2, 0.0)]


# -- commands -------------------------------------------------------------------------------------
def test_set_duty_sends_set_input_vel_at_once(rig: Rig) -> None:
    rig.start()
    rig.motors["base.lf_wheel"].set_duty(0.5)
    sent = rig.sniffed()  # no tick in between
    assert [(m.arbitration_id, bytes(m.data)) for m in sent] == [
        (0x02D, struct.pack("<ff", 5.0, 0.0))]
    assert vel_frames(sent) == [(1, 5.0)]
    rig.motors["base.rf_wheel"].set_duty(-1.0)
    assert vel_frames(rig.sniffed()) == [(2, -10.0)]
    rig.run(0.1)
    assert rig.emu.axes[1].vel == 5.0 and rig.emu.axes[2].vel == -10.0
    assert (1, 5.0) in rig.velocities and (2, -10.0) in rig.velocities
    pos, vel = rig.drv.encoder(1) or (None, None)
    assert vel == 5.0 and pos is not None and 0.4 < pos < 0.6


def test_max_vel_scales_duty() -> None:
    r = Rig(max_vel=2.0)
    try:
        r.start()
        r.motors["base.rf_wheel"].set_duty(0.25)
        assert vel_frames(r.sniffed()) == [(2, 0.5)]
    finally:
        r.close()


def test_refresh_cadence(rig: Rig) -> None:
    rig.start()
    rig.motors["base.lf_wheel"].set_duty(0.3)
    rig.step()
    rig.emu.rx_log.clear()
    rig.run(1.0)
    times = {n: [t for t, m in rig.emu.rx_log
                 if m.arbitration_id == n << 5 | 0x0D] for n in NODES.values()}
    for node, ts in times.items():
        assert 19 <= len(ts) <= 21, (node, ts)
        gaps = [round(b - a, 6) for a, b in itertools.pairwise(ts)]
        assert all(0.05 <= g <= 0.05 + DT for g in gaps), gaps
    assert vel_frames([m for _, m in rig.emu.rx_log]).count((1, 3.0)) == len(times[1])


def test_a_change_goes_out_between_refreshes_and_restarts_the_period(rig: Rig) -> None:
    rig.start()
    rig.run(0.02)
    rig.sniffed()
    rig.motors["base.lf_wheel"].set_duty(0.1)
    assert vel_frames(rig.sniffed()) == [(1, 1.0)]
    rig.run(0.04)
    assert (1, 1.0) not in vel_frames(rig.sniffed())  # not yet: refresh is 50 ms after a send


def test_stop_motors_sends_zeros_to_every_axis_now(rig: Rig) -> None:
    rig.start()
    rig.motors["base.lf_wheel"].set_duty(0.8)
    rig.motors["base.rf_wheel"].set_duty(-0.4)
    rig.run(0.05)
    rig.sniffed()
    rig.drv.stop_motors()
    assert vel_frames(rig.sniffed()) == [(1, 0.0), (2, 0.0)]
    assert all(m.duty == 0.0 for m in rig.motors.values())
    rig.run(0.05)
    assert rig.emu.axes[1].vel == 0.0 and rig.emu.axes[2].vel == 0.0
    assert rig.emu.axes[1].state == 8  # held in closed loop, not dropped


def test_close_sends_zeros_then_idle_and_shuts_the_bus_down(rig: Rig) -> None:
    rig.start()
    rig.motors["base.lf_wheel"].set_duty(0.5)
    rig.sniffed()
    rig.drv.close()
    sent = rig.sniffed()
    assert [(m.arbitration_id, bytes(m.data)) for m in sent] == [
        (0x02D, bytes(8)), (0x04D, bytes(8)),
        (0x027, bytes.fromhex("0100000000000000")), (0x047, bytes.fromhex("0100000000000000")),
    ]
    assert dbc().decode_message(0x07, bytes(sent[2].data)) == {"Axis_Requested_State": 1}
    rig.emu.tick(rig.now + DT)
    assert all(a.state == 1 and a.vel == 0.0 for a in rig.emu.axes.values())
    assert not rig.drv.is_open and rig.drv._bus is None
    rig.drv.close()  # idempotent
    rig.motors["base.lf_wheel"].set_duty(0.5)  # closed: recorded, nothing sent, no error
    rig.drv.tick(rig.now + 2 * DT, DT)
    assert rig.sniffed() == []


# -- faults ---------------------------------------------------------------------------------------
def test_stale_heartbeat_raises_naming_bus_and_node(rig: Rig) -> None:
    rig.start()
    rig.emu.silence(2)
    silenced_at = rig.now
    with pytest.raises(DeviceError) as info:
        rig.run(2.0)
    err = info.value
    assert err.bus == "base_can" and err.device == "node 2 (base.rf_wheel)"
    assert "bus base_can device node 2 (base.rf_wheel): heartbeat stale" in str(err)
    # the last heartbeat came at most 100 ms before the silence; 0.5 s timeout
    assert 0.4 < rig.now - silenced_at <= 0.5 + 2 * DT


def test_no_heartbeat_after_open_raises_after_the_grace_period(rig: Rig) -> None:
    rig.emu.silence()
    rig.open()
    rig.run(rig.drv.grace - DT)  # quiet during the grace period
    with pytest.raises(DeviceError, match=r"node 1 \(base.lf_wheel\): no heartbeat"):
        rig.run(0.1)


def test_axis_error_raises_with_the_error_named(rig: Rig) -> None:
    rig.start()
    rig.motors["base.lf_wheel"].set_duty(0.2)
    rig.run(0.05)
    rig.emu.fail(1)
    with pytest.raises(DeviceError) as info:
        rig.run(0.2)
    assert info.value.bus == "base_can" and "node 1" in info.value.device
    assert "axis error 0x00000040 (MOTOR_FAILED)" in str(info.value)
    assert rig.velocities[-1] == (1, 0.0)  # the emulated axis stopped


def test_leaving_closed_loop_raises(rig: Rig) -> None:
    rig.start()
    rig.sniffer.send(can.Message(arbitration_id=0x047, data=struct.pack("<I4x", 1),
                                 is_extended_id=False))  # someone else idles node 2
    with pytest.raises(DeviceError, match="node 2 .*left CLOSED_LOOP_CONTROL .now IDLE"):
        rig.run(0.2)


def test_axis_that_never_reaches_closed_loop_is_reported_with_its_state() -> None:
    r = Rig(emu_nodes=[1])  # node 2 is played by hand: stuck in IDLE with an encoder error
    try:
        r.open()
        with pytest.raises(DeviceError) as info:
            for i in range(300):
                if i % 10 == 0:
                    r.sniffer.send(can.Message(arbitration_id=0x041, is_extended_id=False,
                                               data=struct.pack("<IB3x", 0x100, 1)))
                r.step()
        assert r.now == pytest.approx(r.drv.grace + DT)
        assert info.value.device == "node 2 (base.rf_wheel)"
        assert ("did not reach CLOSED_LOOP_CONTROL within 1 s of open "
                "(state IDLE, error 0x00000100 (ENCODER_FAILED))") in str(info.value)
    finally:
        r.close()


def test_reopen_after_a_fault_recovers(rig: Rig) -> None:
    rig.start()
    rig.emu.fail(1)
    with pytest.raises(DeviceError):
        rig.run(0.2)
    rig.drv.close()
    rig.run(0.1)
    rig.open()  # the supervisor's retry: Clear_Errors clears the error
    rig.emu.tick(rig.now)
    rig.run(0.3)
    assert rig.drv.ready() and rig.emu.axes[1].error == 0


def test_send_failure_is_a_device_error_from_the_next_tick(rig: Rig) -> None:
    rig.start()
    assert rig.drv._bus is not None
    rig.drv._bus.shutdown()  # the interface vanished under us
    rig.motors["base.lf_wheel"].set_duty(0.2)  # must not raise into the request
    with pytest.raises(DeviceError, match="bus base_can device node 1: CAN send of SET_INPUT_VEL"):
        rig.step()


def test_open_failure_names_the_bus() -> None:
    bad = ODriveBus("ble_can", {"interface": "socketcan", "channel": "ramp-no-such-if"})
    with pytest.raises(DeviceError, match="bus ble_can: cannot open CAN socketcan:ramp-no-such-if"):
        bad.open(0.0)
    assert not bad.is_open
    # An interface python-can does not know can never open: a config error, not a bus that
    # retries "Unknown interface type" once a second for ever.
    with pytest.raises(ConfigError, match=r"buses\.ble_can\.interface: 'no-such-interface' is "
                                          r"not a python-can interface name \(one of "):
        ODriveBus("ble_can", {"interface": "no-such-interface", "channel": "x"})


# -- odds and ends --------------------------------------------------------------------------------
def test_junk_frames_are_counted_not_fatal(rig: Rig) -> None:
    rig.start()
    rig.sniffer.send(can.Message(arbitration_id=0x021, data=b"\x00\x00", is_extended_id=False))
    rig.sniffer.send(can.Message(arbitration_id=0x3E1, data=bytes(8), is_extended_id=False))
    rig.step()
    assert rig.drv.stats["bad"] == 1 and rig.drv.stats["ignored"] >= 1
    rig.run(0.2)
    assert rig.drv.ready()


def test_bus_voltage_request(rig: Rig) -> None:
    rig.start()
    assert rig.drv.bus_voltage(1) is None
    rig.drv.request_bus_voltage(1)
    rtr = rig.sniffed()
    assert len(rtr) == 1 and rtr[0].is_remote_frame and rtr[0].arbitration_id == 0x037
    rig.run(0.02)
    assert rig.drv.bus_voltage(1) == 24.0 and rig.drv.bus_voltage(2) is None


def test_refresh_keeps_the_odrive_watchdog_fed_and_silence_trips_it() -> None:
    r = Rig(emu={"watchdog_timeout": 0.2})
    try:
        r.start()
        r.motors["base.lf_wheel"].set_duty(0.5)
        r.run(1.0)
        assert r.emu.axes[1].state == 8 and r.emu.axes[1].vel == 5.0
        for _ in range(30):  # the supervisor hangs: only the emulator runs
            r.now = round(r.now + DT, 9)
            r.emu.tick(r.now)
        assert r.emu.axes[1].state == 1 and r.emu.axes[1].error == 0x800
        assert r.emu.axes[1].vel == 0.0
    finally:
        r.close()


def test_emulator_ignores_velocity_outside_closed_loop_and_ramps_when_asked() -> None:
    r = Rig(emu={"vel_ramp_rate": 10.0})
    try:
        r.sniffer.send(can.Message(arbitration_id=0x02D, data=struct.pack("<ff", 3.0, 0.0),
                                   is_extended_id=False))
        r.emu.tick(0.0)
        assert r.emu.axes[1].input_vel == 0.0 and r.emu.axes[1].vel == 0.0
        r.start()
        r.motors["base.lf_wheel"].set_duty(0.5)
        r.run(0.1)
        assert r.emu.axes[1].vel == pytest.approx(1.0)  # 10 turns/s^2 for 0.1 s
        r.run(0.5)
        assert r.emu.axes[1].vel == 5.0
    finally:
        r.close()


def test_emulator_estop_clear_errors_and_limits(rig: Rig) -> None:
    rig.start()
    axis = rig.emu.axes[2]
    rig.sniffer.send(can.Message(arbitration_id=0x04F, data=struct.pack("<ff", 2.0, 10.0),
                                 is_extended_id=False))  # Set_Limits vel 2 turns/s
    rig.motors["base.rf_wheel"].set_duty(-0.5)
    rig.run(0.05)
    assert (axis.vel_limit, axis.vel) == (2.0, -2.0)
    rig.sniffer.send(can.Message(arbitration_id=0x042, data=b"", is_extended_id=False))
    with pytest.raises(DeviceError, match="ESTOP_REQUESTED"):
        rig.run(0.2)
    assert (axis.state, axis.error, axis.vel) == (1, 0x4000, 0.0)
    rig.sniffer.send(can.Message(arbitration_id=0x058, data=b"", is_extended_id=False))
    rig.emu.tick(rig.now)
    assert axis.error == 0 and axis.state == 1


def test_a_backlog_beyond_the_drain_limit_is_not_mistaken_for_a_dead_axis(rig: Rig) -> None:
    rig.start()
    rig.drv.on_readable(rig.now)  # nothing left queued from before
    junk = can.Message(arbitration_id=0x029, data=bytes(8), is_extended_id=False)
    for _ in range(600):  # a burst ahead of the heartbeats in the receive queue
        rig.sniffer.send(junk)
    for _ in range(60):  # the supervisor stalls 0.6 s (> heartbeat_timeout) meanwhile
        rig.now = round(rig.now + DT, 9)
        rig.emu.tick(rig.now)
    rig.step()  # drains 512 frames, none a heartbeat: too early to call the axes dead
    assert rig.drv.stats["recv"] >= 512
    rig.run(0.2)
    assert rig.drv.ready()


def test_configuration_is_checked() -> None:
    assert driver_class("can") is ODriveBus
    with pytest.raises(ConfigError, match=r"buses.x.channel: missing"):
        ODriveBus("x", {})
    with pytest.raises(ConfigError, match=r"buses.x.refresh: -1"):
        ODriveBus("x", {"channel": "c", "refresh": -1})
    bus = ODriveBus("x", {"channel": "c"})
    assert (bus.interface, bus.bitrate, bus.heartbeat_timeout, bus.max_vel, bus.refresh) == (
        "virtual", 500000, 0.5, 10.0, 0.05)
    bus.channel("motor", "a", {"node_id": 3})
    with pytest.raises(ValueError, match="node_id 3 is already used by a"):
        bus.channel("motor", "b", {"node_id": 3})
    with pytest.raises(ValueError, match="ODrive node id"):
        bus.channel("motor", "c", {"node_id": 64})


def test_the_emulator_keeps_a_bounded_log_of_received_frames(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """It grew by 4,800 frames per simulated minute, for ever; now it keeps the newest."""
    import firmware_like.odrive

    monkeypatch.setattr(firmware_like.odrive, "RX_LOG_FRAMES", 100)
    r = Rig()
    try:
        r.start()
        r.motors["base.lf_wheel"].set_duty(0.3)
        r.run(2.0)  # about 160 Set_Input_Vel refreshes
        assert len(r.emu.rx_log) == 100
        assert r.emu.rx_log[-1][0] == pytest.approx(r.now)  # the newest are kept
    finally:
        r.close()
