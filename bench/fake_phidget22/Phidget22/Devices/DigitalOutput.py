"""`Phidget22.Devices.DigitalOutput` stand-in."""

from __future__ import annotations

from Phidget22._channel import Channel


class DigitalOutput(Channel):
    def __init__(self) -> None:
        super().__init__()
        self.state = False

    def setState(self, on: bool) -> None:
        self.state = bool(on)
