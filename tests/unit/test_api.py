"""The plugin API (SPEC 10, `ramp.api`) is a small, versioned contract: what it exports is
fixed here, RAMP's own modules and emulators use nothing else of RAMP, the emulator context
offers what RAMP's own emulators use, and a plugin property that raises costs only its row."""

from __future__ import annotations

import ast
import logging
from pathlib import Path
from typing import Any

import pytest

import ramp.api as api
from ramp.registry import emulators, modules
from ramp.simulation.backplane import SimBackplane

ROOT = Path(__file__).resolve().parents[2]

#: API 2.0. Changing this set is changing the contract: bump API_VERSION (a removal or a
#: changed meaning is a new major) and say so in docs/extending/api.md.
API_2_0 = {
    "API_VERSION", "CHANNEL_KINDS", "FUNCTION_KINDS",
    "Module", "DeviceSpec", "BoundDevice", "Function", "Property", "Task", "Kind",
    "Param", "IntParam", "FloatParam", "FlagParam", "Value", "Response",
    "Block", "Field", "Rule", "ConfigError", "DeviceError", "RequestError",
    "Bus", "MotorChannel", "AnalogInput", "DigitalInput", "DigitalOutput", "BridgeInput",
    "ServoChannel",
    "EmulatorContext", "SimWorld", "ServoWorld",
    "Motor", "MOTOR_FIELDS", "Button", "BUTTON_FIELDS", "Voltage", "SystemVoltage",
    "BATTERY_FIELDS", "FILTER_FIELDS", "Led", "LoadCell", "LOAD_CELL_FIELDS", "FaultLatch", "mix",
    "Charge",
}


def test_the_api_is_version_2_and_exports_exactly_its_contract() -> None:
    assert api.API_VERSION == "2.0"
    assert set(api.__all__) == API_2_0 and len(api.__all__) == len(API_2_0)
    for name in api.__all__:
        assert hasattr(api, name), name


def test_marte_s_own_parts_are_not_part_of_the_api() -> None:
    for name in ("ThompsonActuator", "BucketLadder", "LIFT_FIELDS", "POT_FIELDS",
                 "round_half_away", "BaseDrive", "VoltageDisplay", "DISPLAY_FIELDS"):
        assert name not in api.__all__


def _ramp_imports(path: Path) -> set[str]:
    """Every `ramp...` module `path` imports, anywhere in its text."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "ramp")
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and \
                node.module.split(".")[0] == "ramp":
            out.add(node.module)
    return out


def _file_of(entry_value: str) -> Path:
    return ROOT / (entry_value.partition(":")[0].replace(".", "/") + ".py")


def test_ramp_s_own_modules_and_emulators_use_only_the_api() -> None:
    """As a plugin's would: from RAMP, `ramp.api` alone (a module may use the parts beside
    it in `ramp.modules`, MARTE's lift and drive train)."""
    own_modules = [n for n in modules().names() if modules().entry(n).distribution == "ramp"]
    own_emulators = [n for n in emulators().names()
                     if emulators().entry(n).distribution == "ramp"]
    assert {"base", "ble", "diff_base", "demo"} <= set(own_modules)
    files = {_file_of(modules().entry(n).value) for n in own_modules}
    files |= {p for p in (ROOT / "ramp" / "modules").glob("*.py") if p.name != "__init__.py"}
    bad = {}
    for path in sorted(files):
        other = {m for m in _ramp_imports(path)
                 if m != "ramp.api" and not m.startswith("ramp.modules.")}
        if other:
            bad[path.name] = other
    for name in own_emulators:
        path = _file_of(emulators().entry(name).value)
        other = _ramp_imports(path) - {"ramp.api"}
        if other:
            bad[f"{name} ({path.name})"] = other
    assert bad == {}


def _ctx_uses(paths: list[Path]) -> set[str]:
    used: set[str] = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and \
                    node.value.id == "ctx":
                used.add(node.attr)
    return used


def test_the_emulator_context_offers_what_ramp_s_own_emulators_use() -> None:
    """`add_pty_device` was RAMP's Sabertooth emulator's alone; the backplane is the context."""
    members = {n for n in vars(api.EmulatorContext) if not n.startswith("_")}
    members |= set(api.EmulatorContext.__annotations__)
    paths = [*(ROOT / "firmware_like").glob("*.py"), *(ROOT / "examples").rglob("*.py")]
    used = _ctx_uses(paths)
    assert {"add_pty_device", "add_bus_emulator", "shared", "motor_labels"} <= used
    assert used <= members, used - members
    for name in members:
        assert hasattr(SimBackplane, name) or name in ("config", "signals", "dir"), name


class _Gauge(api.Module):
    devices: dict[str, api.DeviceSpec] = {}

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.calls = 0
        self.prop(api.Property("gauge", "ok", "int", lambda: 7))
        self.prop(api.Property("gauge", "broken", "float", self._broken))
        self.prop(api.Property("gauge", "after", "float", lambda: 1.5))

    def _broken(self) -> float:
        self.calls += 1
        raise ZeroDivisionError("a plugin's bug")

    def stop(self) -> None:
        pass

    def is_moving(self) -> bool:
        return False


def test_a_property_that_raises_costs_only_its_row_and_one_traceback(
        caplog: pytest.LogCaptureFixture) -> None:
    module = _Gauge("gauge")
    with caplog.at_level(logging.ERROR):
        for version in ((1, 0), (2, 0), (3, 0)):
            line = module.get_line(version)
        rows: Any = module.rows()
    assert line == (b"gauge:gauge.ok=(7)"
                    b"gauge:gauge.error=(fault,reading gauge.broken raised ZeroDivisionError)"
                    b"gauge:gauge.after=(1.5)")
    assert [r.prop for r in rows] == ["ok", "error", "after"]
    assert module.calls == 4
    tracebacks = [r for r in caplog.records if r.exc_info]
    assert len(tracebacks) == 1 and "gauge.broken" in tracebacks[0].getMessage()


def test_sim_says_at_start_which_driver_it_replaces_for_want_of_an_emulator(
        caplog: pytest.LogCaptureFixture) -> None:
    from ramp.config import parse_config

    config, errors = parse_config(
        "buses:\n  io: {driver: phidget, serial: -1}\n  motors: {driver: sabertooth, "
        "port: /dev/ttyUSB0}\nmodules:\n  m:\n    type: demo\n"
        "    motor: {bus: motors, address: 128, motor: 1}\n    lamp: {bus: io, channel: 0}\n",
        "r.yaml")
    assert not errors and config is not None
    backplane = SimBackplane(config)
    try:
        with caplog.at_level(logging.WARNING, logger="ramp"):
            for bc in config.buses.values():
                backplane.bus_factory(bc).close()
    finally:
        backplane.close()
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warned) == 1 and warned[0].startswith("bus io: driver phidget has no emulator")
