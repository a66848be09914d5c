"""`winchbox` driver: a small motor box with two inputs, on a serial line (any pyserial URL).

Protocol (ASCII lines): the host sends `M<duty>` (-1.000..1.000) on every change and at least
every `refresh` s; the box stops its motor when it hears nothing for 0.5 s, and sends
`I<in0><in1>` (each 0 or 1) every 50 ms. A box silent for `status_timeout` s is a fault.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import serial

from ramp.api import Bus, DeviceError, DigitalInput, Field, MotorChannel


class _Input(DigitalInput):
    def __init__(self, bus: WinchBoxBus, label: str, index: int) -> None:
        super().__init__(bus, label)
        self.index = index

    def read(self) -> bool:
        bus = self.bus
        assert isinstance(bus, WinchBoxBus)
        return bus.inputs[self.index]


class WinchBoxBus(Bus):
    driver_name = "winchbox"
    fields: ClassVar[dict[str, Field]] = {
        "port": Field(str, what="a serial port or pyserial URL"),
        "refresh": Field(float, 0.2, lo=0.02, hi=0.4, what="a refresh period in s"),
        "status_timeout": Field(float, 0.5, lo=0.1, hi=5.0, what="a time in s"),
    }
    channel_fields: ClassVar[dict[str, dict[str, Field]]] = {
        "motor": {},  # the box has one motor
        "digital_in": {"input": Field(int, lo=0, hi=1, what="an input of the box")},
    }

    def __init__(self, name: str, params: Mapping[str, Any]) -> None:
        super().__init__(name, params)
        cfg = self.check_params(params)
        self.port: str = cfg["port"]
        self.refresh: float = cfg["refresh"]
        self.status_timeout: float = cfg["status_timeout"]
        self.inputs = [False, False]
        self._ser: Any = None
        self._buf = b""
        self._sent_at = 0.0
        self._heard_at = 0.0

    def _make_channel(self, kind: str, label: str, spec: dict[str, Any]) -> Any:
        if kind == "motor":
            return MotorChannel(self, label)
        return _Input(self, label, spec["input"])

    def _open(self, now: float) -> None:
        try:
            self._ser = serial.serial_for_url(self.port, timeout=0, write_timeout=0)
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(self.name, f"cannot open {self.port}: {exc}") from exc
        self._buf = b""
        self._heard_at = now
        self._send(now)

    def _send(self, now: float) -> None:
        duty = self.motors[0].duty if self.motors else 0.0
        try:
            self._ser.write(f"M{duty:+.3f}\n".encode("ascii"))
        except (serial.SerialException, OSError) as exc:
            self.failure = DeviceError(self.name, f"write failed: {exc}")
        self._sent_at = now

    def _motor_changed(self, ch: MotorChannel) -> None:
        self._send(self._sent_at)

    def _tick(self, now: float, dt: float) -> None:
        try:
            self._buf += self._ser.read(4096)
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(self.name, f"read failed: {exc}") from exc
        *lines, self._buf = self._buf.split(b"\n")
        for line in lines:
            if len(line) == 3 and line[:1] == b"I":
                self.inputs = [line[1:2] == b"1", line[2:3] == b"1"]
                self._heard_at = now
        if now - self._heard_at > self.status_timeout:
            raise DeviceError(self.name, f"the box sent nothing for {self.status_timeout:g} s")
        if now - self._sent_at >= self.refresh:
            self._send(now)

    def _stop_motors(self) -> None:
        self._send(self._sent_at)

    def _close(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            ser.close()
