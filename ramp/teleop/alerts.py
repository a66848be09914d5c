"""The console's alerts, WPILib-style: persistent, by severity then recency. Sans-IO.

Each alert says what happened and what the operator can do (SPEC 7.1). They are computed
from what the console knows (the robot's poll, the autonomy's view, the links) each time
that changes; an alert keeps the time it was first raised while its cause lasts, and goes
when the cause clears. An error alert offers Take control; a latched fault offers Reset
(`MODULE:DEVICE.reset=()`).

Everything is read from data the robot and the autonomy publish, never from names kept
here: an interlock's severity and advice from describe (`robot:interlock.rule=(NAME,
SEVERITY)`, `robot:interlock.message=(NAME,TEXT)`), latched faults from describe's `reset`
functions, the battery's charge from its `%` row, the localization from the view's enum.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ramp.common.alerts import BATTERY_LOW_PCT, Alert, AlertBook
from ramp.mcp.describe import Catalog, InterlockInfo

#: Localization confidence under which the operator is warned.
CONFIDENCE_LOW = 0.5


def alert_view(alert: Alert, since: float) -> dict[str, Any]:
    """One alert as the console's page takes it: an error offers Take control."""
    return {"id": alert.id, "severity": alert.severity, "title": alert.title,
            "text": alert.text, "reset": alert.reset,
            "takeover": alert.severity == "error", "since": since}


@dataclass
class Inputs:
    """What the alerts are computed from."""

    robot_reachable: bool = True
    robot_detail: str = ""
    values: dict[str, str] = field(default_factory=dict)
    states: dict[str, str] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    #: `module:device.property` keys of the robot's battery readings: a charge in % (the
    #: robot's own battery model) or, for a robot that gives none, volts.
    batteries: tuple[str, ...] = ()
    #: Volts of an empty and a full battery, for volts-only readings (`--battery`).
    battery_range: tuple[float, float] = (17.0, 21.0)
    operator: str = "operator"
    #: None: the console has no --autonomy.
    autonomy: dict[str, Any] | None = None
    #: The robot's interlock rules by name (describe): severity and message.
    interlocks: Mapping[str, InterlockInfo] = field(default_factory=dict)
    #: `module:device.property` keys of latched-fault flags (`latch_flags`).
    latches: tuple[str, ...] = ()


def latch_flags(cat: Catalog) -> tuple[str, ...]:
    """The get rows that say a device's fault is latched, from describe alone: a device with
    a `reset` function (SPEC 2.2 lists one per latchable device) and an int row that no
    function of the device sets (`ble:lift.stalled`, not the `vel` it echoes)."""
    out: list[str] = []
    for module, props in cat.properties.items():
        for p in props:
            names = {f.name for f in cat.functions_of(module, p.device)}
            if "reset" in names and p.type.split(" ")[0] == "int" and p.name not in names:
                out.append(f"{module}:{p.device}.{p.name}")
    return tuple(out)


def active_interlocks(values: Mapping[str, str]) -> list[str]:
    """The names in `robot:interlock.active` (none: `none`)."""
    text = values.get("robot:interlock.active", "")
    return [n for n in text.split(",") if n and n not in ("none", "()")]


def raised(i: Inputs) -> list[Alert]:
    """Every alert whose cause holds now. Each one is something the operator should act on
    or know now (ISA-18.2: no alarm without an action); what only shapes normal work (an
    `info` interlock, a re-localization) is state on the panels and a line in Events."""
    out: list[Alert] = []
    if not i.robot_reachable:
        out.append(Alert("robot-link", "error", "Robot link lost",
                         f"{i.robot_detail or 'no answer'}. The robot's watchdog stops what "
                         "this console moved; the console reconnects by itself and nothing "
                         "resumes without you. Check the network and that `ramp run` is up."))
    for module, state in sorted(i.states.items()):
        why = i.errors.get(module, "") or i.values.get(f"robot:{module}.reason", "")
        if state == "fault":
            out.append(Alert(f"module:{module}", "error", f"Module {module} in fault",
                             f"{why + '. ' if why else ''}Its motion is stopped and its "
                             "requests are refused; the robot retries the device by itself. "
                             "Check its wiring or power."))
        elif state == "detached":
            out.append(Alert(f"module:{module}", "warning", f"Module {module} detached",
                             f"{why + '. ' if why else ''}Its requests are refused until its "
                             "device appears (it attaches by itself): check its cable and "
                             "power if it should be there."))
    for key in i.latches:
        value = i.values.get(key)
        if value is None or value.split(",")[0] not in ("1", "1.0"):
            continue
        module, _, rest = key.partition(":")
        device, _, prop = rest.partition(".")
        out.append(Alert(f"latched:{module}:{device}", "error",
                         f"Latched fault: {module}:{device} {prop}",
                         f"{key}=({value}): its motion is refused until the fault is "
                         "acknowledged. Take control, look at the robot, clear the cause, "
                         f"then Reset (it sends {module}:{device}.reset=()).",
                         reset=f"{module}:{device}"))
    out += _interlocks(i)
    if i.values.get("robot:watchdog.state") == "tripped":
        out.append(Alert("watchdog", "warning", "Watchdog tripped",
                         "Every module was stopped (a silent or lost client, or a stall). "
                         "Motion resumes only on a new command; release and press the "
                         "dead-man to drive."))
    out += _batteries(i)
    if i.autonomy is not None:
        out.extend(_autonomy(i.autonomy, i.values.get("robot:control.owner", ""), i.operator))
    return out


def _interlocks(i: Inputs) -> list[Alert]:
    """One alert per active `warning` or `error` rule, with the rule's own advice."""
    out: list[Alert] = []
    for name in active_interlocks(i.values):
        rule = i.interlocks.get(name, InterlockInfo(name))
        if rule.severity == "info":
            continue
        advice = rule.message or ("Change what trips it (see its `when:` in the robot's "
                                  "YAML, `ramp check --explain`)")
        out.append(Alert(f"interlock:{name}", rule.severity, f"Interlock active: {name}",
                         f"{advice.rstrip('.')}. Meanwhile some motion is refused or "
                         "limited (the robot answers `interlocked`); a latched rule needs "
                         f"robot:interlock.reset=({name}) once its cause is gone."))
    return out


def _batteries(i: Inputs) -> list[Alert]:
    out: list[Alert] = []
    empty, full = i.battery_range
    for key in i.batteries:
        try:
            reading = float(i.values.get(key, "").split(",")[0])
        except ValueError:
            continue
        if key.endswith(".charge"):
            pct, shown = reading, f"{reading:.0f} %"
        else:
            pct = 100.0 * (reading - empty) / (full - empty)
            shown = f"{reading:.2f} V ({max(0.0, pct):.0f} %)"
        if pct < BATTERY_LOW_PCT:
            out.append(Alert(f"battery:{key}", "warning", "Battery low",
                             f"{key} reads {shown}. Finish the run or bring the robot back "
                             "to change it."))
    return out


def _autonomy(a: dict[str, Any], owner: str, operator: str) -> list[Alert]:
    out: list[Alert] = []
    if not a.get("connected"):
        return [Alert("autonomy-view", "warning", "Autonomy view unreachable",
                      f"{a.get('detail', '')}. Teleoperation works without it; the console "
                      "keeps trying. Check that the autonomy runs with --foxglove-port.")]
    if a.get("stale"):
        out.append(Alert("autonomy-view", "warning", "Autonomy view stale",
                         "No news from the autonomy for 3 s: what the map shows may be old. "
                         "Watch the robot itself; take control if in doubt."))
    state, reason = str(a.get("state", "")), str(a.get("reason", ""))
    localization = str(a.get("localization", ""))
    confidence = (a.get("numbers") or {}).get("pose_confidence")
    if state == "waiting_for_operator":
        out.append(Alert("mission-waiting", "error", "Mission waiting for the operator",
                         f"{reason or 'the autonomy gave up'}. Take control, drive or fix "
                         "what is wrong, then Hand back: the mission re-localizes and "
                         "resumes."))
    elif localization == "lost" and state != "paused":
        out.append(Alert("localization", "error", "Localization lost",
                         f"The autonomy stopped and is recovering ({state}"
                         f"{': ' + reason if reason else ''}). If it does not find itself "
                         "again, take control and drive it where the walls are in view."))
    elif localization == "ok" and isinstance(confidence, int | float) \
            and confidence < CONFIDENCE_LOW and state != "paused":
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


class ConsoleAlerts(AlertBook):
    """The console's alerts now, each with when it was first raised."""

    def view(self) -> list[dict[str, Any]]:
        return [alert_view(a, self.since[a.id]) for a in self.alerts]
