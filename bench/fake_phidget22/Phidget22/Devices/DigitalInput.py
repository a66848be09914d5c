"""`Phidget22.Devices.DigitalInput` stand-in: events only on change (there is none)."""

from __future__ import annotations

from collections.abc import Callable

from Phidget22._channel import Channel


class DigitalInput(Channel):
    def setOnStateChangeHandler(self, h: Callable[..., None]) -> None:
        self.handlers["sample"] = h

    def getState(self) -> bool:
        return False
