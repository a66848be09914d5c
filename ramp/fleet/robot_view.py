"""What the agent knows of its robot, learnt from MCP alone: `describe` once per connection,
then `robot.get` and every module's `get` at the poll rate. No robot type is known here:
the drive motors, the battery, the latched faults and the interlocks' severities are all
found in `describe`'s rows, so a new robot joins a fleet without a line of fleet code.

- **Drive motors**: the devices with a `vel` property in a module that has a module-level
  `drive` function (MARTE's four wheels, Scout's two; not Scout's arm).
- **Battery**: a device named `battery`; its `charge` property (%, from the robot's battery
  model) when it has one, its `volt` always when present.
- **Latched faults** (SPEC 2.2): a device with a `reset` function; each of its integer
  properties other than velocities, positions, LEDs and buttons reads non-zero while latched
  (`ble:lift.stalled=(1)`).
- **Interlocks**: `robot:interlock.rule=(NAME[,SEVERITY])` (severity `warning` when absent, as
  SPEC 11's default); `robot:interlock.active=(NAME,...)` or `(none)`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ramp.mcp.messages import Response, Value

_NOT_LATCH = {"vel", "pos", "on", "press", "volt", "charge", "kg"}


@dataclass
class RobotModel:
    """The robot as `describe` tells it."""

    modules: list[str] = field(default_factory=list)
    rules: dict[str, str] = field(default_factory=dict)
    functions: dict[str, list[tuple[str, str, tuple[Value, ...]]]] = field(default_factory=dict)
    properties: dict[str, list[tuple[str, str, tuple[Value, ...]]]] = field(default_factory=dict)
    drive_motors: list[tuple[str, str]] = field(default_factory=list)
    battery_charge: tuple[str, str] | None = None
    battery_volt: tuple[str, str] | None = None
    latches: list[tuple[str, str, str]] = field(default_factory=list)

    def add_robot_rows(self, rows: list[Response]) -> None:
        for r in rows:
            if r.module != "robot" or not r.values:
                continue
            if r.device == "robot" and r.prop == "module":
                self.modules.append(str(r.values[0]))
            elif r.device == "interlock" and r.prop == "rule":
                severity = str(r.values[1]) if len(r.values) > 1 else "warning"
                self.rules[str(r.values[0])] = severity

    def add_module_rows(self, module: str, rows: list[Response]) -> None:
        funcs = self.functions.setdefault(module, [])
        props = self.properties.setdefault(module, [])
        for r in rows:
            if r.module != module or not r.values:
                continue
            if r.prop == "function":
                funcs.append((r.device, str(r.values[0]), r.values[1:]))
            elif r.prop == "property":
                props.append((r.device, str(r.values[0]), r.values[1:]))
        self._derive(module)

    def _derive(self, module: str) -> None:
        funcs = self.functions[module]
        props = self.properties[module]
        if any(d == module and f == "drive" for d, f, _ in funcs):
            self.drive_motors += [(module, d) for d, p, _ in props if p == "vel" and d != module]
        for d, p, _ in props:
            if d == "battery" and p == "charge" and self.battery_charge is None:
                self.battery_charge = (module, d)
            if d == "battery" and p == "volt" and self.battery_volt is None:
                self.battery_volt = (module, d)
        resettable = {d for d, f, _ in funcs if f == "reset"}
        self.latches += [(module, d, p) for d, p, info in props
                         if d in resettable and p not in _NOT_LATCH
                         and (not info or info[0] == "int")]


@dataclass
class RobotStatus:
    """One poll's reading: `robot.get` and every attached module's `get`."""

    owner: str = "none"
    module_states: dict[str, str] = field(default_factory=dict)
    active_interlocks: list[str] = field(default_factory=list)
    watchdog: str = "idle"
    values: dict[str, tuple[Value, ...]] = field(default_factory=dict)

    @classmethod
    def read(cls, rows: list[Response], modules: list[str]) -> RobotStatus:
        st = cls()
        known = set(modules)
        for r in rows:
            if r.prop == "error":
                continue
            if r.module == "robot":
                first = str(r.values[0]) if r.values else ""
                if r.device == "control" and r.prop == "owner":
                    st.owner = first
                elif r.device == "watchdog" and r.prop == "state":
                    st.watchdog = first
                elif r.device == "interlock" and r.prop == "active":
                    st.active_interlocks = [str(v) for v in r.values if str(v) != "none"]
                elif r.prop == "state" and r.device in known:
                    st.module_states[r.device] = first
                elif r.prop == "reason" and r.device in known:
                    st.values[f"robot:{r.device}.reason"] = r.values
            else:
                st.values[f"{r.module}:{r.device}.{r.prop}"] = r.values
        return st

    def number(self, module: str, device: str, prop: str) -> float | None:
        v = self.values.get(f"{module}:{device}.{prop}")
        if not v or isinstance(v[0], str):
            return None
        return float(v[0])

    def driving(self, model: RobotModel) -> bool:
        return any((self.number(m, d, "vel") or 0.0) != 0.0 for m, d in model.drive_motors)

    def latched(self, model: RobotModel) -> list[tuple[str, str, str]]:
        return [(m, d, p) for m, d, p in model.latches if (self.number(m, d, p) or 0) != 0]
