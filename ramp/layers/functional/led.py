"""Led: on, off or blinking, driven by the scheduler's `now` (the thesis ran a thread per
LED; here one task ticks them all and the phase comes from the clock)."""

from __future__ import annotations

from typing import Literal

from ramp.hal.interfaces import DigitalOutput

Mode = Literal["off", "on", "blink"]


class Led:
    """One LED on a digital output. Blinking starts lit and has a 50 % duty cycle."""

    def __init__(self, channel: DigitalOutput) -> None:
        self.channel = channel
        self.mode: Mode = "off"
        self.rate_hz = 0.0
        self._phase_start: float | None = None

    @property
    def is_on(self) -> bool:
        """What was asked for: True when set on (steady) - not the blink phase."""
        return self.mode == "on"

    @property
    def lit(self) -> bool:
        """Whether the output is driven right now."""
        return self.channel.state

    def set(self, on: bool) -> None:
        """Steady on or off, written at once."""
        self.mode = "on" if on else "off"
        self._phase_start = None
        self.channel.write(on)

    def blink(self, rate_hz: float) -> None:
        """Blink at `rate_hz` full periods per second from the next tick; calling it again
        with the same rate keeps the phase (so callers may repeat it every tick)."""
        if rate_hz <= 0:
            raise ValueError("blink rate must be positive")
        if self.mode == "blink" and self.rate_hz == rate_hz:
            return
        self.mode = "blink"
        self.rate_hz = rate_hz
        self._phase_start = None

    def tick(self, now: float) -> None:
        if self.mode != "blink":
            self.channel.write(self.mode == "on")
            return
        if self._phase_start is None:
            self._phase_start = now
        phase = ((now - self._phase_start) * self.rate_hz) % 1.0
        self.channel.write(phase < 0.5 - 1e-9)
