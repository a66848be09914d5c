"""RAMP's state in VDA 5050's words (SPEC 14; the table in docs/operating/fleet.md).

Pure functions of what MCP said (`RobotModel`, `RobotStatus`) and of the agent's own state,
so each line of the mapping table has a test of its own.
"""

from __future__ import annotations

from typing import Any

from ramp.fleet import vda5050 as v
from ramp.fleet.robot_view import RobotModel, RobotStatus

#: The name the autonomy acquires control with (SPEC 6.3).
AUTONOMY_OWNER = "autonomy"


def operating_mode(owner: str, fleet_order_running: bool) -> str:
    """AUTOMATIC while the autonomy holds control on its own, SEMIAUTOMATIC while it drives
    the fleet's order, MANUAL while an operator holds control, SERVICE when nobody does."""
    if owner == AUTONOMY_OWNER:
        return v.SEMIAUTOMATIC if fleet_order_running else v.AUTOMATIC
    if owner in ("none", ""):
        return v.SERVICE
    return v.MANUAL


def battery_state(model: RobotModel, status: RobotStatus) -> tuple[dict[str, Any],
                                                                    list[dict[str, Any]]]:
    """(batteryState, information entries): the charge from the battery model's `charge`
    property; without one, the voltage with batteryCharge 0 and an information entry that
    says the charge is unknown (the schema requires a number)."""
    volt = status.number(*model.battery_volt, "volt") if model.battery_volt else None
    charge = status.number(*model.battery_charge, "charge") if model.battery_charge else None
    if charge is not None:
        return v.battery(max(0.0, min(100.0, charge)), voltage=volt), []
    what = (f"the battery reports only its voltage ({volt:.2f} V); no battery model gives "
            "its charge") if volt is not None else "the robot has no battery device"
    return v.battery(0.0, voltage=volt), [v.info("batteryChargeUnknown", what)]


def errors(model: RobotModel, status: RobotStatus) -> list[dict[str, Any]]:
    """Module faults (FATAL), detached modules (WARNING), latched faults (FATAL: the device
    is stopped until an operator resets it) and active warning/error interlocks (WARNING /
    FATAL; `info` rules shape normal work and are not errors)."""
    out = []
    for module, state in sorted(status.module_states.items()):
        if state == "fault":
            why = status.values.get(f"robot:{module}.reason", ())
            because = f" ({why[0]})" if why else ""
            out.append(v.error("moduleFault", v.FATAL, f"module {module} is in fault{because}:"
                               " its motion is stopped until its device works again",
                               {"module": module}))
        elif state == "detached":
            out.append(v.error("moduleDetached", v.WARNING, f"module {module} is detached "
                               "(its device is not present)", {"module": module}))
    for m, d, p in status.latched(model):
        out.append(v.error("latchedFault", v.FATAL, f"{m}:{d}.{p} is latched: {m}:{d} refuses "
                           "motion until an operator resets it",
                           {"device": f"{m}:{d}", "property": p},
                           hint=f"{m}:{d}.reset=() once the cause is cleared"))
    for name in status.active_interlocks:
        severity = model.rules.get(name, "warning")
        if severity == "info":
            continue
        out.append(v.error("interlockActive", v.FATAL if severity == "error" else v.WARNING,
                           f"interlock {name} is active", {"interlock": name,
                                                             "severity": severity}))
    return out


def interlock_info(model: RobotModel, status: RobotStatus) -> list[dict[str, Any]]:
    """Active `info` interlocks, shown as state (SPEC 11)."""
    return [v.info("interlockActive", f"interlock {n} is active", {"interlock": n})
            for n in status.active_interlocks if model.rules.get(n, "warning") == "info"]


def safety(model: RobotModel, status: RobotStatus) -> tuple[str, bool]:
    """(eStop, fieldViolation): REMOTE while a latched fault holds a device stopped (it is
    acknowledged remotely, by an operator's MCP reset); a field violation while an `error`
    interlock is active."""
    e_stop = "REMOTE" if status.latched(model) else "NONE"
    field = any(model.rules.get(n, "warning") == "error" for n in status.active_interlocks)
    return e_stop, field
