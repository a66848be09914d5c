"""Voltage and SystemVoltage: the power rail as the operator should see it.

`Voltage` turns the ADC pin voltage into rail volts (Phidget 1135 Precision Voltage Sensor:
2.5 V out at 0 V in, 0.0681 V per volt, so V_rail = (Vout - 2.5) / 0.0681). `SystemVoltage`
low-pass filters it on the scheduler tick: motor starts pull the LiPo rail down for a few
hundred milliseconds, and neither the operator nor the LED display should react to that.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ramp.hal.interfaces import AnalogInput
from ramp.layers.functional.battery import MODEL_FIELDS, MODEL_RULES
from ramp.schema import Block, Field

#: YAML keys of the battery device (defaults: the 1135's fixed conversion), and the pack's
#: model for its charge (`ramp.layers.functional.battery`).
BATTERY_FIELDS = Block({
    "offset": Field(float, 2.5, -10.0, 10.0, what="the pin voltage at 0 V on the rail"),
    "scale": Field(float, 0.0681, 0.001, 10.0, what="pin volts per rail volt"),
    **MODEL_FIELDS,
}, MODEL_RULES)

#: Settings block `battery_filter`: the low-pass time constant in seconds.
FILTER_FIELDS = Block({
    "time_constant": Field(float, 2.0, 0.01, 600.0, what="a filter time constant in s"),
})


class Voltage:
    """The instantaneous rail voltage: (Vout - offset) / scale."""

    def __init__(self, channel: AnalogInput, offset: float = 2.5, scale: float = 0.0681) -> None:
        if scale == 0:
            raise ValueError("scale must not be zero")
        self.channel = channel
        self.offset = offset
        self.scale = scale

    @classmethod
    def from_params(cls, channel: AnalogInput, params: Mapping[str, Any]) -> Voltage:
        return cls(channel, float(params.get("offset", 2.5)), float(params.get("scale", 0.0681)))

    def read(self) -> float:
        """Rail volts from the newest ADC sample."""
        return (self.channel.read() - self.offset) / self.scale


class SystemVoltage:
    """First-order low-pass of `Voltage` with time constant `tau`, stepped by `tick`.

    The update y += (x - y)(1 - exp(-dt/tau)) is exact for any dt, so the filter behaves the
    same at any task rate. The first sample seeds the output: no slow climb from 0 V at boot.
    """

    def __init__(self, source: Voltage, tau: float = 2.0) -> None:
        if tau <= 0:
            raise ValueError("the filter time constant must be positive")
        self.source = source
        self.tau = tau
        self._value: float | None = None

    def tick(self, now: float, dt: float) -> None:
        x = self.source.read()
        if self._value is None or not math.isfinite(self._value):
            self._value = x
        elif dt > 0:
            self._value += (x - self._value) * (1.0 - math.exp(-dt / self.tau))

    @property
    def value(self) -> float:
        """The filtered rail voltage (the instantaneous one until the first tick)."""
        if self._value is None:
            return self.source.read()
        return self._value
