"""The fleet page's alerts, in the console's model (SPEC 7.1): error, warning or info; kept while
their cause holds, with the time they were first raised; ordered by severity then recency; each
says what happened and what the supervisor can do. Sans-IO.

Everything comes from what the robots publish (their `connection` and `state`) and from what
the page itself did (a Stop all not yet confirmed), never from a robot type: an error the robot
reports keeps its own type, description and hint, FATAL being an error and WARNING a warning.
The model itself (the alert, the book of first-raised times, the order, the battery's low
mark) is the console's, from `ramp.common.alerts`.
"""

from __future__ import annotations

from typing import Any

from ramp.common.alerts import BATTERY_LOW_PCT, Alert, AlertBook

#: VDA 5050 error levels in the console's severities.
LEVELS = {"FATAL": "error", "WARNING": "warning"}
#: An ONLINE robot silent this long is stale: `state` comes at least every 30 s (SPEC 14) and
#: `visualization` at 2 Hz, so this is a dead agent whose will the broker has not yet sent.
SILENT_S = 35.0
#: A robot that has not confirmed a stopPause this long after it was sent is an error: the
#: supervisor must stop it some other way.
STOP_LATE_S = 2.0


def robot_alerts(serial: str, connection: str, silent_s: float | None,
                 state: dict[str, Any], stop_pending_s: float | None) -> list[Alert]:
    """What one robot's latest messages call for. `silent_s`: seconds since its last message
    (None: never heard); `stop_pending_s`: seconds since a stopPause it has not confirmed."""
    out: list[Alert] = []
    if stop_pending_s is not None and stop_pending_s >= STOP_LATE_S:
        out.append(Alert(f"{serial}:stop-late", "error", f"{serial} has not confirmed the stop",
                         f"No state with the stopPause and driving=false {stop_pending_s:.0f} s "
                         "after it was sent. Stop it another way: its own console's STOP or "
                         "its emergency stop.", serial=serial))
    if connection == "CONNECTIONBROKEN":
        out.append(Alert(f"{serial}:connection", "error", f"{serial}: connection broken",
                         "Its agent vanished (the broker sent its last will). The robot's "
                         "watchdog stops what the agent commanded, but the fleet can neither "
                         "see nor stop it: use its own console, and restart its agent.",
                         serial=serial))
    elif connection == "OFFLINE":
        out.append(Alert(f"{serial}:connection", "warning", f"{serial}: offline",
                         "Its agent left in an orderly way: the fleet cannot command it until "
                         "the agent runs again.", serial=serial))
    elif silent_s is not None and silent_s >= SILENT_S:
        out.append(Alert(f"{serial}:silent", "warning", f"{serial}: silent",
                         f"No message for {silent_s:.0f} s though it said ONLINE: its agent or "
                         "its link may be down. Check the robot at its console.", serial=serial))
    for e in state.get("errors", []):
        if not isinstance(e, dict):
            continue
        kind = str(e.get("errorType", "error"))
        refs = ",".join(f"{r.get('referenceKey')}={r.get('referenceValue')}"
                        for r in e.get("errorReferences", []) if isinstance(r, dict))
        hint = str(e.get("errorHint") or "")
        text = str(e.get("errorDescription") or kind)
        out.append(Alert(f"{serial}:error:{kind}:{refs}", LEVELS.get(str(e.get("errorLevel")),
                                                                      "warning"),
                         f"{serial}: {kind}",
                         f"{text.rstrip('.')}. {hint.rstrip('.') + '. ' if hint else ''}"
                         "Act on it at the robot's own console.", serial=serial))
    charge = state.get("batteryState", {}).get("batteryCharge")
    unknown = any(isinstance(i, dict) and i.get("infoType") == "batteryChargeUnknown"
                  for i in state.get("information", []))
    if isinstance(charge, int | float) and not unknown and charge < BATTERY_LOW_PCT:
        out.append(Alert(f"{serial}:battery", "warning", f"{serial}: battery low",
                         f"{charge:.0f} %: finish its task or bring it back to change it.",
                         serial=serial))
    return out


class Board(AlertBook):
    """The page's alerts now, each with the time its cause was first seen."""

    def view(self, now: float) -> list[dict[str, Any]]:
        """The page's list, with how long each has been raised."""
        return [{"id": a.id, "severity": a.severity, "title": a.title, "text": a.text,
                 "serial": a.serial, "for_s": round(now - self.since[a.id], 1)}
                for a in self.alerts]
