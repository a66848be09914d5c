"""The mapping table (docs/operating/fleet.md), line by line, on MCP rows as a backend
answers them; and the `fleet:` block's checks."""

from __future__ import annotations

from pathlib import Path

from ramp.config.loader import parse_config
from ramp.fleet import mapping
from ramp.fleet import vda5050 as v
from ramp.fleet.pause import PauseStore
from ramp.fleet.robot_view import RobotModel, RobotStatus
from ramp.fleetconf import parse
from ramp.mcp.messages import Response
from ramp.mcp.protocol import parse_response_line
from tests.fleet.schemas import validate


def rows(text: str) -> list[Response]:
    """Response rows from an MCP response line, parsed as the agent's link parses them."""
    return parse_response_line(text.encode())


def marte(charge: bool = False, severity: bool = True) -> RobotModel:
    m = RobotModel()
    m.add_robot_rows(rows("robot:robot.module=(base)robot:robot.module=(ble)"
                          + ("robot:interlock.rule=(digging_creep,info)"
                             "robot:interlock.rule=(bin_up_slow,warning)"
                             "robot:interlock.rule=(bumper,error)" if severity else
                             "robot:interlock.rule=(digging_creep)")))
    m.add_module_rows("base", rows(
        "base:base.function=(drive,int -100..100,float)base:lf_wheel.function=(vel,int)"
        "base:lf_wheel.property=(vel,int)base:rb_wheel.property=(vel,int)"
        "base:battery.property=(volt,float,V)base:user_led.property=(on,int)"
        + ("base:battery.property=(charge,float,%)" if charge else "")))
    m.add_module_rows("ble", rows(
        "ble:lift.function=(vel,int -100..100)ble:lift.function=(reset)"
        "ble:lift.property=(vel,int)ble:lift.property=(pos,float)"
        "ble:lift.property=(stalled,int)ble:chain.property=(vel,int)"))
    return m


def status(model: RobotModel, text: str) -> RobotStatus:
    return RobotStatus.read(rows(text), model.modules)


def test_drive_motors_battery_and_latches_come_from_describe() -> None:
    m = marte(charge=True)
    assert m.drive_motors == [("base", "lf_wheel"), ("base", "rb_wheel")]
    assert m.battery_charge == ("base", "battery") and m.battery_volt == ("base", "battery")
    assert m.latches == [("ble", "lift", "stalled")]


def test_driving_is_any_drive_motor_not_the_chain() -> None:
    m = marte()
    assert not status(m, "ble:chain.vel=(40)base:lf_wheel.vel=(0)").driving(m)
    assert status(m, "base:rb_wheel.vel=(-5)").driving(m)


def test_battery_charge_or_a_marked_unknown() -> None:
    m = marte(charge=True)
    bat, info = mapping.battery_state(m, status(m, "base:battery.charge=(87.5)"
                                                   "base:battery.volt=(25.1)"))
    assert bat == {"batteryCharge": 87.5, "batteryVoltage": 25.1, "charging": False}
    assert info == []
    m = marte()
    bat, info = mapping.battery_state(m, status(m, "base:battery.volt=(20.9)"))
    assert bat["batteryCharge"] == 0.0 and bat["batteryVoltage"] == 20.9
    assert info[0]["infoType"] == "batteryChargeUnknown" and "20.90 V" in \
        info[0]["infoDescription"]


def test_errors_faults_latches_and_interlock_levels() -> None:
    m = marte()
    s = status(m, "robot:base.state=(ok)robot:ble.state=(fault)"
                  "robot:ble.reason=(bus ble_motors: no answer)"
                  "robot:interlock.active=(digging_creep,bin_up_slow,bumper)"
                  "ble:lift.stalled=(1)")
    errs = mapping.errors(m, s)
    kinds = [(e["errorType"], e["errorLevel"]) for e in errs]
    assert ("moduleFault", "FATAL") in kinds and ("latchedFault", "FATAL") in kinds
    [fault] = [e for e in errs if e["errorType"] == "moduleFault"]
    assert "module ble is in fault (bus ble_motors: no answer)" in fault["errorDescription"]
    levels = {e["errorReferences"][0]["referenceValue"]: e["errorLevel"] for e in errs
              if e["errorType"] == "interlockActive"}
    assert levels == {"bin_up_slow": "WARNING", "bumper": "FATAL"}  # info rules: not errors
    assert [i["infoType"] for i in mapping.interlock_info(m, s)] == ["interlockActive"]
    assert mapping.safety(m, s) == ("REMOTE", True)
    quiet = status(m, "robot:interlock.active=(none)ble:lift.stalled=(0)")
    assert mapping.errors(m, quiet) == [] and mapping.safety(m, quiet) == ("NONE", False)
    # A rule without a severity is a warning (SPEC 11's default).
    old = marte(severity=False)
    s = status(old, "robot:interlock.active=(digging_creep)")
    assert mapping.errors(old, s)[0]["errorLevel"] == "WARNING"
    validate("state", v.state(v.Headers("RAMP", "x"), v.StateFields(errors=errs)))


def test_operating_mode() -> None:
    assert mapping.operating_mode("autonomy", False) == "AUTOMATIC"
    assert mapping.operating_mode("autonomy", True) == "SEMIAUTOMATIC"
    assert mapping.operating_mode("ana", True) == "MANUAL"
    assert mapping.operating_mode("none", False) == "SERVICE"


def test_owner_and_states_are_read() -> None:
    m = marte()
    s = status(m, "robot:control.owner=(ana)robot:watchdog.state=(armed)robot:base.state=(ok)")
    assert (s.owner, s.watchdog, s.module_states) == ("ana", "armed", {"base": "ok"})


def test_pause_store_survives_and_fails_safe(tmp_path: Path) -> None:
    p = PauseStore(tmp_path, "r1")
    assert not p.load()
    p.set(True, "stopPause a1")
    assert PauseStore(tmp_path, "r1").load()
    p.path.write_text("{broken")
    assert PauseStore(tmp_path, "r1").load()  # unreadable: paused, never cleared
    p.set(False)
    assert not PauseStore(tmp_path, "r1").load()


FLEET_YAML = """
buses: {io: {driver: sim}}
modules: {demo: {motor: {bus: io}, lamp: {bus: io}}}
fleet:
  serial: SERIAL
  broker: BROKER
  tls: {ca: ca.crt, cert: r.crt}
"""


def fleet_yaml(serial: str, broker: str) -> str:
    return FLEET_YAML.replace("SERIAL", serial).replace("BROKER", broker)


def test_fleet_block_errors_name_their_line() -> None:
    _, errors = parse_config(fleet_yaml("a/b", "h:0"), "r.yaml")
    text = [str(e) for e in errors]
    assert any("r.yaml:5" in t and "fleet.serial" in t for t in text), text
    assert any("r.yaml:6" in t and "fleet.broker" in t for t in text), text
    assert any("fleet.tls.key" in t and "missing" in t for t in text), text


def test_fleet_block_parses(tmp_path: Path) -> None:
    cfg = parse({"serial": "marte-1", "broker": "10.0.0.5:8883", "autonomy": "127.0.0.1:5590",
                 "tls": {"ca": "c/ca.crt", "cert": "c/m.crt", "key": "c/m.key"}}, tmp_path)
    assert cfg.manufacturer == "RAMP" and cfg.broker == ("10.0.0.5", 8883)
    assert cfg.autonomy == ("127.0.0.1", 5590)
    assert cfg.tls is not None and cfg.tls.ca == tmp_path / "c/ca.crt"
    _, errors = parse_config(fleet_yaml("m1", "h:1883")
                             .replace("  tls: {ca: ca.crt, cert: r.crt}\n", ""), "r.yaml")
    assert errors == []
