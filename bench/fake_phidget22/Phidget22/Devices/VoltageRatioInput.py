"""`Phidget22.Devices.VoltageRatioInput` stand-in: a steady bridge ratio."""

from __future__ import annotations

from collections.abc import Callable

from Phidget22 import _library
from Phidget22._channel import Channel


class VoltageRatioInput(Channel):
    def setOnVoltageRatioChangeHandler(self, h: Callable[..., None]) -> None:
        self.handlers["sample"] = h

    def setBridgeGain(self, gain: int) -> None:
        pass

    def setBridgeEnabled(self, on: bool) -> None:
        pass

    def setVoltageRatioChangeTrigger(self, v: float) -> None:
        pass

    def _sample(self) -> float | None:
        self._emit("sample", _library.RATIO)
        return self.interval_ms / 1000.0
