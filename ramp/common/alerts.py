"""The alert model the operator's pages share, WPILib-style: the console (SPEC 7.1) and the
fleet page (SPEC 14). Sans-IO, and a leaf, so both pages use it without importing each other.

An alert is an error, a warning or an info; it says what happened and what to do; it is kept
while its cause holds, with the time it was first raised; the list is ordered by severity,
then the newest first. What raises one is each page's own business.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import KW_ONLY, dataclass

#: Most urgent first: an error is acted on now (the console offers Take control).
SEVERITIES = ("error", "warning", "info")
#: Battery charge (%) under which it is low, on either page.
BATTERY_LOW_PCT = 20.0


@dataclass(frozen=True)
class Alert:
    """One alert: `id` is stable while its cause lasts, so it keeps its first-raised time."""

    id: str
    severity: str
    title: str
    text: str
    _: KW_ONLY  # what only one page uses, by name
    #: The console: `MODULE:DEVICE` whose latched fault a Reset button acknowledges.
    reset: str = ""
    #: The fleet page: the robot it is about.
    serial: str = ""


class AlertBook:
    """The alerts shown now, each with when it was first raised."""

    def __init__(self) -> None:
        self.since: dict[str, float] = {}
        self.alerts: list[Alert] = []

    def update(self, alerts: Iterable[Alert], now: float) -> bool:
        """Take the alerts raised now (gone causes are forgotten); returns whether the list
        changed."""
        current = list(alerts)
        since = {a.id: self.since.get(a.id, now) for a in current}
        rank = {s: n for n, s in enumerate(SEVERITIES)}
        ordered = sorted(current, key=lambda a: (rank.get(a.severity, 9), -since[a.id], a.id))
        changed = ordered != self.alerts
        self.since, self.alerts = since, ordered
        return changed
