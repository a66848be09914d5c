"""VoltageDisplay: three LEDs that show how much battery is left, at a glance, across an arena.

Sequence (thesis 5.3.2.1: all on near full, then one by one each LED blinks and goes out).
With the thresholds of DISPLAY_FIELDS, from full to empty:

    level  rail voltage V               high   mid    low
      5    V >= high_blink              on     on     on
      4    high_off <= V < high_blink   blink  on     on
      3    mid_blink <= V < high_off    off    on     on
      2    mid_off <= V < mid_blink     off    blink  on
      1    low_blink <= V < mid_off     off    off    on
      0    V < low_blink                off    off    blink   (critical: stop and charge)

The low LED never goes fully out, so a dark row always means "supervisor not running".
The level drops as soon as V is below a threshold but rises only when V is `hysteresis` above
it, so a rail hovering at a threshold does not flicker between two levels. Defaults suit
MARTE's rail (two 5S LiPo packs in parallel: 21.0 V full, 17-21 V usable).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ramp.api import Block, Field, Led, Rule

#: Settings block `voltage_display`: thresholds in rail volts (descending), blink rate, band.
_ORDER = ("low_blink", "mid_off", "mid_blink", "high_off", "high_blink")
_DESCENDING = ("voltage display thresholds must be five strictly descending values: "
               "high_blink > high_off > mid_blink > mid_off > low_blink")

DISPLAY_FIELDS = Block({
    "high_blink": Field(float, 20.0, 0.0, 100.0, what="volts below which the high LED blinks"),
    "high_off": Field(float, 19.4, 0.0, 100.0, what="volts below which the high LED is off"),
    "mid_blink": Field(float, 18.8, 0.0, 100.0, what="volts below which the mid LED blinks"),
    "mid_off": Field(float, 18.2, 0.0, 100.0, what="volts below which the mid LED is off"),
    "low_blink": Field(float, 17.6, 0.0, 100.0, what="volts below which the low LED blinks"),
    "blink_hz": Field(float, 2.0, 0.1, 20.0, what="a blink rate in Hz"),
    "hysteresis": Field(float, 0.1, 0.0, 5.0, what="volts a level must be exceeded by"),
}, [Rule(lambda v: all(v[a] < v[b] for a, b in zip(_ORDER, _ORDER[1:], strict=False)),
         _DESCENDING)])

#: Per level (0..5): the modes of (high, mid, low).
PATTERN: tuple[tuple[str, str, str], ...] = (
    ("off", "off", "blink"),
    ("off", "off", "on"),
    ("off", "blink", "on"),
    ("off", "on", "on"),
    ("blink", "on", "on"),
    ("on", "on", "on"),
)


class VoltageDisplay:
    """Maps a (filtered) rail voltage onto the high, mid and low LEDs."""

    def __init__(self, high: Led, mid: Led, low: Led, thresholds: tuple[float, ...],
                 blink_hz: float = 2.0, hysteresis: float = 0.1) -> None:
        """`thresholds` ascending: (low_blink, mid_off, mid_blink, high_off, high_blink)."""
        pairs = zip(thresholds, thresholds[1:], strict=False)
        if len(thresholds) != 5 or any(a >= b for a, b in pairs):
            raise ValueError(_DESCENDING)
        self.leds = (high, mid, low)
        self.thresholds = thresholds
        self.blink_hz = blink_hz
        self.hysteresis = hysteresis
        self.level: int | None = None

    @classmethod
    def from_settings(cls, high: Led, mid: Led, low: Led, s: Mapping[str, Any]
                      ) -> VoltageDisplay:
        return cls(high, mid, low, tuple(float(s[k]) for k in _ORDER),
                   float(s["blink_hz"]), float(s["hysteresis"]))

    def level_for(self, volts: float) -> int:
        """The level for `volts`, with hysteresis against the current level."""
        raw = sum(1 for t in self.thresholds if volts >= t)
        if self.level is None or raw <= self.level:
            return raw
        # Rising: climb only past thresholds exceeded by the hysteresis band.
        return max(self.level, sum(1 for t in self.thresholds if volts >= t + self.hysteresis))

    def tick(self, now: float, volts: float) -> None:
        self.level = self.level_for(volts)
        for led, mode in zip(self.leds, PATTERN[self.level], strict=True):
            if mode == "blink":
                led.blink(self.blink_hz)
            elif led.mode != mode:
                led.set(mode == "on")
            led.tick(now)
