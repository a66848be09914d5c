"""LoadCell: the bin's load in kg from the bridge ratio, kg = (ratio - offset) * kg_per_mv_v.

The cell sits on the actuator mount, so its zero moves with the empty bin's weight and the
lift angle: `tare()` lets the operator zero it with the bin empty, in the pose they weigh in.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ramp.errors import RequestError
from ramp.hal.interfaces import BridgeInput
from ramp.schema import Block, Field, Rule

#: YAML keys of the load cell (kg_per_mv_v is required: no default could be right).
LOAD_CELL_FIELDS = Block({
    "kg_per_mv_v": Field(float, lo=-1e6, hi=1e6, what="kg per mV/V of bridge output"),
    "offset_mv_v": Field(float, 0.0, -1000.0, 1000.0, what="the bridge reading at 0 kg"),
}, [Rule(lambda v: v["kg_per_mv_v"] != 0, "kg_per_mv_v must not be zero", "kg_per_mv_v")])


class LoadCell:
    """Calibrated weight from a Wheatstone bridge input."""

    def __init__(self, channel: BridgeInput, kg_per_mv_v: float, offset_mv_v: float = 0.0
                 ) -> None:
        if kg_per_mv_v == 0:
            raise ValueError("kg_per_mv_v must not be zero")
        self.channel = channel
        self.kg_per_mv_v = kg_per_mv_v
        self.offset_mv_v = offset_mv_v

    @classmethod
    def from_params(cls, channel: BridgeInput, params: Mapping[str, Any]) -> LoadCell:
        return cls(channel, float(params["kg_per_mv_v"]), float(params.get("offset_mv_v", 0.0)))

    @property
    def kg(self) -> float:
        return (self.channel.read() - self.offset_mv_v) * self.kg_per_mv_v

    def tare(self) -> None:
        """Take the current reading as zero (kept until restart; the YAML offset is the boot
        value)."""
        reading = self.channel.read()
        if not math.isfinite(reading):
            raise RequestError("fault", "no reading from the load cell to tare with")
        self.offset_mv_v = reading
