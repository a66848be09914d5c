"""Functional layer: the algorithms and controllers behind each module's requests.

Components are small and hierarchical (thesis 5.3.2): a `BaseDrive` uses four `Motor`s, a
`VoltageDisplay` uses a `SystemVoltage` reading and three `Led`s. None of them owns a thread
or reads a clock: periodic work happens in `tick(now, ...)` methods that the module's
scheduler tasks call, and every read of hardware returns the HAL's newest sample.

Each component declares the YAML keys it is tuned by (`MOTOR_FIELDS`, `LIFT_FIELDS` ...) as a
`ramp.schema.Block`, with the rules that span several keys. Those are checked once, before a
component is built (by the config loader, or by the module that builds it); the components
then trust what they are given and what the router has validated: they assert, never clamp.
"""

from __future__ import annotations

from ramp.layers.functional.base_drive import BaseDrive, mix
from ramp.layers.functional.bucket_ladder import BucketLadder
from ramp.layers.functional.button import BUTTON_FIELDS, Button
from ramp.layers.functional.latch import FaultLatch
from ramp.layers.functional.led import Led
from ramp.layers.functional.load_cell import LOAD_CELL_FIELDS, LoadCell
from ramp.layers.functional.motor import MOTOR_FIELDS, Motor
from ramp.layers.functional.thompson_actuator import LIFT_FIELDS, POT_FIELDS, ThompsonActuator
from ramp.layers.functional.voltage import (
    BATTERY_FIELDS,
    FILTER_FIELDS,
    SystemVoltage,
    Voltage,
)
from ramp.layers.functional.voltage_display import DISPLAY_FIELDS, VoltageDisplay

__all__ = [
    "BATTERY_FIELDS", "BUTTON_FIELDS", "DISPLAY_FIELDS", "FILTER_FIELDS", "LIFT_FIELDS",
    "LOAD_CELL_FIELDS", "MOTOR_FIELDS", "POT_FIELDS",
    "BaseDrive", "BucketLadder", "Button", "FaultLatch", "Led", "LoadCell", "Motor",
    "SystemVoltage", "ThompsonActuator", "Voltage", "VoltageDisplay", "mix",
]
