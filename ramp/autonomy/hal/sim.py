"""`sim` drivers: the IMU and the gimbal bound to their HAL-level emulators.

USB cannot be emulated (SPEC 6.2), so in simulation these stand where the Phidget22 drivers
stand: the emulator objects (`firmware_like/imu.py`, `firmware_like/servo.py`) are handed in
by the one simulation entry point, exactly as the backend's `sim` bus takes the world; this
module never imports them. They behave like the `phidget` drivers at the HAL: samples come in
ticks, commands reach the controller only while it is attached and are all sent again when it
re-attaches, and an unplugged board is a fault that clears when it comes back.
"""

from __future__ import annotations

import logging
from typing import Any, Protocol

from ramp.autonomy.config import GimbalConfig, ImuConfig, ServoConfig
from ramp.autonomy.hal.interfaces import Imu, ImuSample, PanTilt, Servo
from ramp.errors import DeviceError

log = logging.getLogger(__name__)


class SpatialEmulator(Protocol):
    """What `firmware_like.imu.ImuEmulator` offers this driver."""

    attached: bool

    def poll(self) -> list[Any]: ...  # SpatialData: t, timestamp_ms, acceleration, ...
    def set_data_interval(self, ms: int) -> None: ...
    def zero_gyro(self) -> None: ...


class ServoChannel(Protocol):
    """What `firmware_like.servo.ServoEmulator` offers this driver."""

    engaged: bool

    @property
    def position_deg(self) -> float | None: ...
    def set_target(self, deg: float) -> None: ...
    def set_velocity_limit(self, dps: float) -> None: ...
    def set_acceleration(self, dps2: float) -> None: ...
    def set_engaged(self, on: bool) -> None: ...
    def take_reached(self) -> list[float]: ...


class GimbalEmulator(Protocol):
    attached: bool
    pan: Any  # ServoChannel
    tilt: Any  # ServoChannel


class SimImu(Imu):
    driver_name = "sim"

    def __init__(self, config: ImuConfig, name: str = "imu", *, emulator: SpatialEmulator
                 ) -> None:
        super().__init__(config, name)
        self.emulator = emulator

    def _open(self, now: float) -> None:
        self._attached = False
        self.emulator.poll()  # what was measured while nobody listened is gone

    def _tick(self, now: float, dt: float) -> None:
        emu = self.emulator
        if emu.attached and not self._attached:
            emu.set_data_interval(self.config.data_interval_ms)
            self._attach(now)
            log.info("%s: simulated PhidgetSpatial attached", self.name)
        elif not emu.attached and self._attached:
            self._detach("simulated PhidgetSpatial detached")
        if not self._attached:
            return
        polled = emu.poll()
        if polled:
            self._accept_all([ImuSample(s.t, s.timestamp_ms, s.acceleration, s.angular_rate,
                                        s.magnetic_field) for s in polled], now)

    def _zero_gyro(self) -> None:
        self.emulator.zero_gyro()

    def _close(self) -> None:
        self._attached = False


class SimServo(Servo):
    def __init__(self, gimbal: SimPanTilt, config: ServoConfig, channel: ServoChannel) -> None:
        super().__init__(gimbal.name, config)
        self.gimbal = gimbal
        self.channel = channel

    def _live(self) -> bool:
        return self.gimbal.is_open and self.attached

    def _apply_target(self, deg: float) -> None:
        if self._live():
            self.channel.set_target(deg)

    def _apply_velocity_limit(self, dps: float) -> None:
        if self._live():
            self.channel.set_velocity_limit(dps)

    def _apply_acceleration(self, dps2: float) -> None:
        if self._live():
            self.channel.set_acceleration(dps2)

    def _apply_engaged(self, on: bool) -> None:
        if self._live():
            self.channel.set_engaged(on)

    def _send_all(self) -> None:
        """Everything the controller forgot at its power-on."""
        ch = self.channel
        ch.set_velocity_limit(self.velocity_limit_dps)
        ch.set_acceleration(self.acceleration_dps2)
        if self.target_deg is not None:
            ch.set_target(self.target_deg)
            if self.engaged:
                ch.set_engaged(True)


class SimulatedGimbal(PanTilt):
    """What both simulated gimbals (`SimPanTilt` here, `SimLinkPanTilt` over the sensor
    link) do as their controller comes and goes; each axis has `_send_all`."""

    def _follow_controller(self, axis: Any, there: bool, how: str = "") -> bool:
        """One axis follows its controller's presence: on arrival every command is sent
        again (what the controller forgot at its power-on) and the gimbal's fault clears
        once both axes are back; on loss the axis forgets its position and the gimbal
        faults (`_detached`). True while the axis is attached."""
        if there and not axis.attached:
            axis.attached = True
            axis._send_all()
            log.info("%s: simulated servo controller %s attached%s", self.name, axis.label,
                     how)
            if self.attached:
                self._clear_fault()
        elif not there and axis.attached:
            axis.attached = False
            axis.position_deg = None
            self._set_fault(self._detached(axis))
        return bool(axis.attached)

    def _detached(self, axis: Any) -> DeviceError:
        return DeviceError(self.name, f"simulated servo controller channel "
                           f"{axis.config.channel} detached", axis.label)


class SimPanTilt(SimulatedGimbal):
    driver_name = "sim"

    def __init__(self, config: GimbalConfig, name: str = "gimbal", *,
                 emulator: GimbalEmulator) -> None:
        self.emulator = emulator
        super().__init__(config, name)

    def _make_servo(self, config: ServoConfig) -> Servo:
        channel = self.emulator.pan if config.name == "pan" else self.emulator.tilt
        return SimServo(self, config, channel)

    def _axes(self) -> tuple[SimServo, SimServo]:
        pan, tilt = self.pan, self.tilt
        assert isinstance(pan, SimServo) and isinstance(tilt, SimServo)
        return (pan, tilt)

    def _open(self, now: float) -> None:
        for axis in self._axes():
            axis.attached = False
            axis.position_deg = None

    def _tick(self, now: float, dt: float) -> None:
        there = self.emulator.attached
        for axis in self._axes():
            if axis.attached != there:  # arrived or lost (otherwise nothing to follow)
                self._follow_controller(axis, there)
            if not axis.attached:
                continue
            channel = axis.channel
            for deg in channel.take_reached():
                axis._report_reached(deg)
            if axis.engaged:
                pos = channel.position_deg
                if pos is not None:
                    axis._report_position(pos)

    def _close(self) -> None:
        for axis in self._axes():
            axis.attached = False
            axis.position_deg = None
