"""`Phidget22.Devices.VoltageInput` stand-in: a steady voltage every data interval."""

from __future__ import annotations

from collections.abc import Callable

from Phidget22 import _library
from Phidget22._channel import Channel


class VoltageInput(Channel):
    def setOnVoltageChangeHandler(self, h: Callable[..., None]) -> None:
        self.handlers["sample"] = h

    def setSensorType(self, t: int) -> None:
        pass

    def setVoltageChangeTrigger(self, v: float) -> None:
        pass

    def _sample(self) -> float | None:
        self._emit("sample", _library.VOLTS.get(self.channel, _library.DEFAULT_VOLTS))
        return self.interval_ms / 1000.0
