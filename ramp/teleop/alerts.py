"""The console's alerts, WPILib-style: persistent, by severity then recency. Sans-IO.

Each alert says what happened and what the operator can do (SPEC 7.1). They are computed
from what the console knows (the robot's poll, the autonomy's view, the links) each time
that changes; an alert keeps the time it was first raised while its cause lasts, and goes
when the cause clears. An error alert offers Take control; a latched fault offers Reset
(`MODULE:DEVICE.reset=()`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

SEVERITIES = ("error", "warning", "info")
#: Localization confidence under which the operator is warned.
CONFIDENCE_LOW = 0.5
#: Battery charge (%, from the console's EMPTY:FULL volts) under which it is low.
BATTERY_LOW_PCT = 20.0
#: Mission states in which the autonomy is recovering a lost localization.
RECOVERY = ("relevel", "rescan", "relocalize")
#: States before the first fix: a zero confidence there is no alarm.
BEFORE_FIX = ("", "idle", "acquire_control", "initial_localization", "done")
#: Properties whose value 1 is a latched fault (SPEC 2.2: `ble:lift.stalled=(1)`).
LATCHED_PROPS = ("stalled", "jammed", "latched", "fault")


@dataclass(frozen=True)
class Alert:
    """One alert as the page shows it."""

    id: str
    severity: str
    title: str
    text: str
    #: `MODULE:DEVICE` whose latched fault a Reset button acknowledges.
    reset: str = ""

    def view(self, since: float) -> dict[str, Any]:
        return {"id": self.id, "severity": self.severity, "title": self.title,
                "text": self.text, "reset": self.reset,
                "takeover": self.severity == "error", "since": since}


@dataclass
class Inputs:
    """What the alerts are computed from."""

    robot_reachable: bool = True
    robot_detail: str = ""
    values: dict[str, str] = field(default_factory=dict)
    states: dict[str, str] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    #: `module:device.property` keys of the robot's volt readings.
    batteries: tuple[str, ...] = ()
    battery_range: tuple[float, float] = (17.0, 21.0)
    operator: str = "operator"
    #: None: the console has no --autonomy.
    autonomy: dict[str, Any] | None = None


def raised(i: Inputs) -> list[Alert]:
    """Every alert whose cause holds now."""
    out: list[Alert] = []
    if not i.robot_reachable:
        out.append(Alert("robot-link", "error", "Robot link lost",
                         f"{i.robot_detail or 'no answer'}. The robot's watchdog stops what "
                         "this console moved; the console reconnects by itself and nothing "
                         "resumes without you. Check the network and that `ramp run` is up."))
    for module, state in sorted(i.states.items()):
        why = i.errors.get(module, "")
        if state == "fault":
            out.append(Alert(f"module:{module}", "error", f"Module {module} in fault",
                             f"{why + '. ' if why else ''}Its motion is stopped and its "
                             "requests are refused; the robot retries the device by itself. "
                             "Check its wiring or power."))
        elif state == "detached":
            out.append(Alert(f"module:{module}", "warning", f"Module {module} detached",
                             f"{why + '. ' if why else ''}It attaches by itself when its "
                             "device appears."))
    for key, value in sorted(i.values.items()):
        module, _, rest = key.partition(":")
        device, _, prop = rest.partition(".")
        if prop in LATCHED_PROPS and value.split(",")[0] in ("1", "1.0"):
            out.append(Alert(f"latched:{module}:{device}", "error",
                             f"Latched fault: {module}:{device} {prop}",
                             f"{key}=({value}): its motion is refused until the fault is "
                             "acknowledged. Take control, look at the robot, clear the cause, "
                             "then Reset (it sends "
                             f"{module}:{device}.reset=()).", reset=f"{module}:{device}"))
    active = i.values.get("robot:interlock.active", "")
    if active and active not in ("none", "()"):
        out.append(Alert("interlock", "warning", f"Interlock active: {active}",
                         "Some motion is refused or limited while it holds (the robot "
                         "answers `interlocked`). Change what trips it (e.g. the lift's "
                         "position); a latched interlock needs robot:interlock.reset."))
    if i.values.get("robot:watchdog.state") == "tripped":
        out.append(Alert("watchdog", "warning", "Watchdog tripped",
                         "Every module was stopped (a silent or lost client, or a stall). "
                         "Motion resumes only on a new command; release and press the "
                         "dead-man to drive."))
    empty, full = i.battery_range
    for key in i.batteries:
        try:
            volts = float(i.values.get(key, "").split(",")[0])
        except ValueError:
            continue
        pct = 100.0 * (volts - empty) / (full - empty)
        if pct < BATTERY_LOW_PCT:
            out.append(Alert(f"battery:{key}", "warning", "Battery low",
                             f"{key} reads {volts:.2f} V ({max(0.0, pct):.0f} %). Finish the "
                             "run or bring the robot back to change it."))
    if i.autonomy is not None:
        out.extend(_autonomy(i.autonomy, i.values.get("robot:control.owner", ""), i.operator))
    return out


def _autonomy(a: dict[str, Any], owner: str, operator: str) -> list[Alert]:
    out: list[Alert] = []
    if not a.get("connected"):
        return [Alert("autonomy-view", "warning", "Autonomy view unreachable",
                      f"{a.get('detail', '')}. Teleoperation works without it; the console "
                      "keeps trying.")]
    if a.get("stale"):
        out.append(Alert("autonomy-view", "warning", "Autonomy view stale",
                         "No news from the autonomy for 3 s: what the map shows may be old. "
                         "Watch the robot itself; take control if in doubt."))
    state, reason = str(a.get("state", "")), str(a.get("reason", ""))
    confidence = (a.get("numbers") or {}).get("pose_confidence")
    if state == "waiting_for_operator":
        out.append(Alert("mission-waiting", "error", "Mission waiting for the operator",
                         f"{reason or 'the autonomy gave up'}. Take control, drive or fix "
                         "what is wrong, then Hand back: the mission re-localizes and "
                         "resumes."))
    elif a.get("lost") and state in RECOVERY + ("stop", "resume"):
        out.append(Alert("localization", "error", "Localization lost",
                         f"The autonomy stopped and is recovering ({state}"
                         f"{': ' + reason if reason else ''}). If it does not find itself "
                         "again, take control and drive it where the walls are in view."))
    elif state in RECOVERY:
        out.append(Alert("localization", "info", "Re-localizing",
                         f"The autonomy is finding its pose again ({state}) before it goes "
                         "on; it does not drive meanwhile."))
    elif isinstance(confidence, int | float) and confidence < CONFIDENCE_LOW \
            and state not in BEFORE_FIX and state != "paused":
        out.append(Alert("confidence", "warning", "Localization confidence low",
                         f"Confidence {confidence:.2f} (under {CONFIDENCE_LOW}). The autonomy "
                         "may be lost soon; be ready to take control."))
    if state == "paused":
        who = f"{owner} has" if owner and owner != "none" else "an operator took"
        mine = " (you)" if owner == operator else ""
        out.append(Alert("mission-paused", "info", "Mission paused",
                         f"{who} control{mine}. Hand back to let the autonomy re-localize "
                         "and resume."))
    return out


class AlertBook:
    """The alerts shown now, each with when it was first raised."""

    def __init__(self) -> None:
        self._since: dict[str, float] = {}
        self.alerts: list[Alert] = []

    def update(self, alerts: list[Alert], now: float) -> bool:
        """Take the alerts raised now; returns whether the list changed."""
        since = {a.id: self._since.get(a.id, now) for a in alerts}
        rank = {s: n for n, s in enumerate(SEVERITIES)}
        ordered = sorted(alerts, key=lambda a: (rank.get(a.severity, 9), -since[a.id], a.id))
        changed = ordered != self.alerts
        self._since, self.alerts = since, ordered
        return changed

    def view(self) -> list[dict[str, Any]]:
        return [a.view(self._since[a.id]) for a in self.alerts]
