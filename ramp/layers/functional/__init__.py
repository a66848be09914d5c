"""Functional layer: the algorithms and controllers behind each module's requests.

Components are small and hierarchical (thesis 5.3.2): a `Motor` wraps a HAL motor channel, a
`SystemVoltage` filters a `Voltage` reading. None of them owns a thread or reads a clock:
periodic work happens in `tick(now, ...)` methods that the module's scheduler tasks call, and
every read of hardware returns the HAL's newest sample. These are the generic parts
`ramp.api` offers every module; MARTE's own (its drive train, lift, bucket ladder and battery
display) live beside MARTE's modules in `ramp.modules`.

Each component declares the YAML keys it is tuned by (`MOTOR_FIELDS`, `BUTTON_FIELDS` ...) as
a `ramp.schema.Block`, with the rules that span several keys. Those are checked once, before a
component is built (by the config loader, or by the module that builds it); the components
then trust what they are given and what the router has validated: they assert, never clamp.
"""

from __future__ import annotations

from ramp.layers.functional.base_drive import mix
from ramp.layers.functional.button import BUTTON_FIELDS, Button
from ramp.layers.functional.latch import FaultLatch
from ramp.layers.functional.led import Led
from ramp.layers.functional.load_cell import LOAD_CELL_FIELDS, LoadCell
from ramp.layers.functional.motor import MOTOR_FIELDS, Motor
from ramp.layers.functional.voltage import (
    BATTERY_FIELDS,
    FILTER_FIELDS,
    SystemVoltage,
    Voltage,
)

__all__ = [
    "BATTERY_FIELDS", "BUTTON_FIELDS", "FILTER_FIELDS", "LOAD_CELL_FIELDS", "MOTOR_FIELDS",
    "Button", "FaultLatch", "Led", "LoadCell", "Motor", "SystemVoltage", "Voltage", "mix",
]
