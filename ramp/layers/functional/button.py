"""Button: a debounced digital input (the docking buttons that "feel" the arena wall).

A contact bounces for a few milliseconds and a wheel bump can make it chatter; autonomy
decides "docked" from these, so a change counts only once it has held for `debounce` s.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ramp.hal.interfaces import DigitalInput
from ramp.schema import Block, Field

#: YAML keys of every button device.
BUTTON_FIELDS = Block({
    "debounce": Field(float, 0.02, 0.0, 1.0, what="a debounce time in s"),
    "active_low": Field(bool, False),
})


class Button:
    """Pressed once the (possibly inverted) input has held a new level for `debounce` s."""

    def __init__(self, channel: DigitalInput, debounce: float = 0.02,
                 active_low: bool = False) -> None:
        self.channel = channel
        self.debounce = debounce
        self.active_low = active_low
        self._pressed: bool | None = None
        self._candidate = False
        self._since = 0.0

    @classmethod
    def from_params(cls, channel: DigitalInput, params: Mapping[str, Any]) -> Button:
        return cls(channel, float(params.get("debounce", 0.02)),
                   bool(params.get("active_low", False)))

    @property
    def pressed(self) -> bool:
        return bool(self._pressed)

    def tick(self, now: float) -> None:
        raw = bool(self.channel.read()) != self.active_low
        if self._pressed is None:  # first sample: nothing to debounce against
            self._pressed = self._candidate = raw
            self._since = now
            return
        if raw != self._candidate:
            self._candidate = raw
            self._since = now
        if self._candidate != self._pressed and now - self._since >= self.debounce - 1e-9:
            self._pressed = self._candidate
