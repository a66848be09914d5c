"""Functional layer: the algorithms and controllers behind each module's requests.

Components are small and hierarchical (thesis 5.3.2): a `BaseDrive` uses four `Motor`s, a
`VoltageDisplay` uses a `SystemVoltage` reading and three `Led`s. None of them owns a thread
or reads a clock: periodic work happens in `tick(now, ...)` methods that the module's
scheduler tasks call, and every read of hardware returns the HAL's newest sample.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ramp.errors import ConfigError
from ramp.layers.functional.base_drive import BaseDrive, mix
from ramp.layers.functional.bucket_ladder import BucketLadder
from ramp.layers.functional.button import BUTTON_FIELDS, Button
from ramp.layers.functional.led import Led
from ramp.layers.functional.load_cell import LOAD_CELL_FIELDS, LoadCell
from ramp.layers.functional.motor import MOTOR_FIELDS, Motor
from ramp.layers.functional.thompson_actuator import LIFT_FIELDS, POT_FIELDS, ThompsonActuator
from ramp.layers.functional.voltage import BATTERY_FIELDS, FILTER_FIELDS, SystemVoltage, Voltage
from ramp.layers.functional.voltage_display import DISPLAY_FIELDS, VoltageDisplay
from ramp.schema import Field

__all__ = [
    "BATTERY_FIELDS", "BUTTON_FIELDS", "DISPLAY_FIELDS", "FILTER_FIELDS", "LIFT_FIELDS",
    "LOAD_CELL_FIELDS", "MOTOR_FIELDS", "POT_FIELDS",
    "BaseDrive", "BucketLadder", "Button", "Led", "LoadCell", "Motor", "SystemVoltage",
    "ThompsonActuator", "Voltage", "VoltageDisplay", "block", "channel", "mix",
]


def block(fields: Mapping[str, Field], values: Mapping[str, Any] | None, where: str
          ) -> dict[str, Any]:
    """A settings block with defaults filled in for keys the loader did not supply.

    The loader normally passes complete blocks; filling here keeps a module constructible
    from a partial dict (tests, `ramp sim`) without repeating every default.
    """
    out: dict[str, Any] = {}
    given = dict(values or {})
    for key, f in fields.items():
        if key in given:
            out[key] = given[key]
        elif f.required:
            raise ConfigError(f"missing; expected {f.expected()}", key=f"{where}.{key}")
        else:
            out[key] = f.default
    return out


def channel(devices: Mapping[str, Any], name: str, kind: type) -> tuple[Any, Mapping[str, Any]]:
    """The HAL channel and checked keys of device `name`, which must be a `kind` channel.

    `devices` maps names to bound devices (anything with `channel` and `params`)."""
    try:
        bound = devices[name]
    except KeyError:
        raise ConfigError("missing device", key=name) from None
    ch = bound.channel
    if not isinstance(ch, kind):
        raise ConfigError(f"expected a {kind.__name__} channel, got {type(ch).__name__}",
                          key=name)
    return ch, dict(bound.params)
