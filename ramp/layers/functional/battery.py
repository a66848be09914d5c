"""Battery charge in %, from the rail voltage and the robot's own battery model (YAML).

A voltage says little about charge until you know the pack: Scout's fresh 3S LiPo reads
12.6 V, MARTE's fresh 5S reads 21 V. So the battery device names its pack, either as
`cells` and `chemistry` (a resting-voltage curve per cell from the table below, times the
cells) or as its own `curve`, a table of `[volts, percent]` rows (a pack measured on the
bench). Between rows the charge is interpolated; outside them it is 0 or 100.

The figure is the pack's resting (open-circuit) charge: under load the rail sags and the
charge reads low for as long as the load lasts (the voltage is already low-pass filtered,
`battery_filter`). It is `MODULE:battery.charge=(87.5)` in get, unit `%`; the console's
gauge and the fleet's VDA 5050 `batteryState.batteryCharge` read it.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from typing import Any

from ramp.schema import Field, Rule

#: Resting voltage of one cell -> charge %, per chemistry (typical figures from cell makers'
#: discharge curves at low rate and room temperature; a measured `curve` beats them).
CELL_CURVES: dict[str, tuple[tuple[float, float], ...]] = {
    "lipo": ((3.27, 0.0), (3.61, 5.0), (3.69, 10.0), (3.73, 20.0), (3.77, 30.0),
             (3.80, 40.0), (3.84, 50.0), (3.87, 60.0), (3.95, 70.0), (4.02, 80.0),
             (4.11, 90.0), (4.15, 95.0), (4.20, 100.0)),
    "liion": ((3.00, 0.0), (3.45, 5.0), (3.60, 15.0), (3.68, 30.0), (3.74, 45.0),
              (3.80, 55.0), (3.88, 65.0), (3.96, 75.0), (4.05, 85.0), (4.13, 95.0),
              (4.20, 100.0)),
    "lifepo4": ((2.80, 0.0), (3.00, 9.0), (3.20, 17.0), (3.22, 30.0), (3.25, 40.0),
                (3.26, 50.0), (3.27, 60.0), (3.30, 70.0), (3.32, 80.0), (3.35, 90.0),
                (3.40, 99.0), (3.60, 100.0)),
    "nimh": ((1.00, 0.0), (1.10, 5.0), (1.20, 30.0), (1.25, 60.0), (1.30, 80.0),
             (1.40, 100.0)),
    "lead_acid": ((1.93, 0.0), (1.97, 10.0), (2.00, 25.0), (2.03, 50.0), (2.07, 75.0),
                  (2.12, 100.0)),
}
CHEMISTRIES = tuple(CELL_CURVES)


def _curve_ok(values: Mapping[str, Any]) -> bool:
    curve = values.get("curve") or []
    try:
        rows = [(float(v), float(p)) for v, p in curve]
    except (TypeError, ValueError):
        return False
    return len(rows) >= 2 and all(0.0 <= p <= 100.0 for _, p in rows) and all(
        b[0] > a[0] and b[1] >= a[1] for a, b in zip(rows, rows[1:], strict=False))


#: The model's keys on the battery device (beside the sensor's `offset` and `scale`).
MODEL_FIELDS = {
    "cells": Field(int, 0, 0, 48, what="the number of cells in series (0: not given)"),
    "chemistry": Field(str, "lipo", choices=CHEMISTRIES),
    "curve": Field(list, [], what="a list of [volts, percent] rows"),
}
MODEL_RULES = (
    Rule(lambda v: not v.get("curve") or _curve_ok(v),
         "expected at least two [volts, percent] rows, volts rising, percent 0-100 and "
         "never falling", key="curve"),
    Rule(lambda v: not (v.get("curve") and v.get("cells")),
         "give either cells and chemistry or a curve, not both", key="curve"),
)


class ChargeModel:
    """Pack volts -> charge % by linear interpolation in a table of (volts, %) rows."""

    def __init__(self, rows: Sequence[tuple[float, float]], *, guessed: bool = False) -> None:
        self.volts = [float(v) for v, _ in rows]
        self.pct = [float(p) for _, p in rows]
        #: No model in the YAML: the cell count is guessed from the first reading.
        self.guessed = guessed

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> ChargeModel | None:
        """The model the device's checked keys give; None when they give none (then the
        cell count is guessed from the first reading: `guess`)."""
        curve = params.get("curve") or []
        if curve:
            return cls([(float(v), float(p)) for v, p in curve])
        cells = int(params.get("cells") or 0)
        if cells:
            return cls.of_cells(cells, str(params.get("chemistry", "lipo")))
        return None

    @classmethod
    def of_cells(cls, cells: int, chemistry: str, *, guessed: bool = False) -> ChargeModel:
        return cls([(v * cells, p) for v, p in CELL_CURVES[chemistry]], guessed=guessed)

    @classmethod
    def guess(cls, volts: float, chemistry: str = "lipo") -> ChargeModel:
        """A pack of `chemistry` with the fewest cells that `volts` does not overfill (a
        robot started on a fresh or part-used pack reads right; an almost empty one may be
        taken for one cell fewer, hence the YAML model)."""
        full = CELL_CURVES[chemistry][-1][0]
        cells = max(1, math.ceil(volts / full - 0.02)) if volts > 0 else 1
        return cls.of_cells(cells, chemistry, guessed=True)

    def charge(self, volts: float) -> float:
        """Charge in %, 0-100, to one decimal."""
        v, p = self.volts, self.pct
        if math.isnan(volts) or volts <= v[0]:  # NaN reads empty: never a false full
            return 0.0
        if volts >= v[-1]:
            return 100.0
        i = bisect.bisect_right(v, volts)
        frac = (volts - v[i - 1]) / (v[i] - v[i - 1])
        return round(p[i - 1] + frac * (p[i] - p[i - 1]), 1)


class Charge:
    """The charge get row of a battery device: its model applied to the filtered volts."""

    def __init__(self, volts: Any, params: Mapping[str, Any]) -> None:
        self._volts = volts  # a callable returning the filtered rail volts
        self.chemistry = str(params.get("chemistry", "lipo"))
        self.model = ChargeModel.from_params(params)

    def read(self) -> float:
        volts = float(self._volts())
        if self.model is None:
            self.model = ChargeModel.guess(volts, self.chemistry)
        return self.model.charge(volts)
