"""Config errors name the file, line, key path and what was expected; all are reported."""

from __future__ import annotations

import re
from pathlib import Path

from ramp.cli import main
from ramp.config import check_config, parse_config

GOOD = """\
server: {host: 127.0.0.1, port: 0}
watchdog: {timeout: 0.5}
scheduler: {rate_hz: 50}
buses:
  io: {driver: sim}
modules:
  demo: {motor: {bus: io}, lamp: {bus: io}}
"""


def errors_of(text: str) -> list[str]:
    cfg, errors = parse_config(text, "ramp.yaml")
    assert cfg is None
    return [str(e) for e in errors]


def test_good_config_loads_frozen_values() -> None:
    cfg, errors = parse_config(GOOD, "ramp.yaml")
    assert errors == []
    assert cfg is not None
    assert cfg.server.port == 0 and cfg.server.max_line == 4096 and cfg.server.max_clients == 8
    assert cfg.watchdog_timeout == 0.5 and cfg.rate_hz == 50.0
    assert cfg.modules["demo"].devices["motor"].bus == "io"


def test_every_error_is_reported_with_line_and_key() -> None:
    text = """\
server: {port: 70000, colour: blue}
watchdog: {timeout: 0}
buses:
  io: {driver: warp}
  io2: {driver: sim}
modules:
  demo:
    motor: {bus: nowhere}
    lamp: {bus: io2, volume: 11}
  x: {type: rocket}
"""
    errs = errors_of(text)
    assert "ramp.yaml:1: server.port: 70000 is not a TCP port (0-65535)" in errs
    assert any(e.startswith("ramp.yaml:1: server.colour: unknown key") for e in errs)
    assert "ramp.yaml:2: watchdog.timeout: 0 is not a timeout in seconds (0.05-60)" in errs
    assert any(e.startswith("ramp.yaml:4: buses.io.driver: unknown driver 'warp'") for e in errs)
    assert any(e.startswith("ramp.yaml:8: modules.demo.motor.bus: 'nowhere' is not a bus")
               for e in errs)
    assert any(e.startswith("ramp.yaml:9: modules.demo.lamp.volume: unknown key") for e in errs)
    assert any(e.startswith("ramp.yaml:10: modules.x.type: unknown module type 'rocket'")
               for e in errs)
    assert len(errs) == 7


def test_missing_device_and_duplicate_key() -> None:
    errs = errors_of("buses:\n  io: {driver: sim}\nmodules:\n  demo:\n    motor: {bus: io}\n"
                     "    motor: {bus: io}\n")
    assert any("modules.demo.motor: key given twice" in e for e in errs)
    assert any("modules.demo.lamp: missing; a demo module needs a digital_out device" in e
               for e in errs)


def test_not_yaml_and_wrong_shapes() -> None:
    assert errors_of("server: [1, 2\n")[0].startswith("ramp.yaml:")
    assert errors_of("- a\n- b\n") == [
        "ramp.yaml:1: expected a mapping of sections at the top, got a list"]
    errs = errors_of("server: 5\nrobots: {}\n")
    assert "ramp.yaml:1: server: expected a mapping, got an integer" in errs
    assert any(e.startswith("ramp.yaml:2: robots: unknown section") for e in errs)


def test_robot_is_a_reserved_module_name() -> None:
    errs = errors_of("buses:\n  io: {driver: sim}\nmodules:\n  robot: {type: demo}\n")
    assert any("modules.robot: `robot` is reserved" in e for e in errs)


def test_ramp_check_command(tmp_path: Path, capsys: object) -> None:
    good = tmp_path / "good.yaml"
    good.write_text(GOOD)
    assert main(["check", str(good)]) == 0
    bad = tmp_path / "bad.yaml"
    bad.write_text("watchdog: {timeout: -1}\nscheduler: {rate_hz: fast}\n")
    assert main(["check", str(bad)]) == 2  # a configuration error, as from ramp run
    cfg, errors = check_config(bad)
    assert len(errors) == 2
    assert main(["check", str(tmp_path / "missing.yaml")]) == 2


def test_checks_spanning_several_keys_are_reported_with_their_line() -> None:
    from tests.harness import MARTE_YAML

    text = MARTE_YAML.replace("volts_at_0: 0.6, volts_at_1: 4.4",
                              "volts_at_0: 2.0, volts_at_1: 2.0")
    errs = errors_of(text)
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "lift_pot:" in t)
    assert len(errs) == 1 and errs[0].startswith(f"ramp.yaml:{line}: modules.ble.lift_pot")


def test_marte_config_with_a_bad_sabertooth_address() -> None:
    from tests.harness import MARTE_YAML

    text = MARTE_YAML.replace("address: 128, motor: 1}", "address: 140, motor: 1}")
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "address: 140" in t)
    assert errors_of(text) == [f"ramp.yaml:{line}: modules.base.lf_wheel.address: 140 is not a "
                               "Sabertooth address (128-135)"]


def test_two_buses_on_one_serial_port_are_a_config_error() -> None:
    from tests.harness import MARTE_YAML

    ports = re.findall(r"\bport: (/dev/[^,}\s]+)", MARTE_YAML)
    assert len(set(ports)) >= 2, ports
    text = MARTE_YAML.replace(ports[1], ports[0])
    line = [i for i, t in enumerate(text.splitlines(), 1) if f"port: {ports[0]}" in t][1]
    errs = errors_of(text)
    assert len(errs) == 1, errs
    assert errs[0].startswith(f"ramp.yaml:{line}: buses.") and ".port: " in errs[0]
    assert "is already the port of bus" in errs[0]


def test_a_watchdog_shorter_than_a_tick_is_an_error_at_its_line() -> None:
    text = "scheduler: {rate_hz: 1}\nwatchdog:\n  timeout: 0.05\nmodules: {}\nbuses: {}\n"
    cfg, errors = parse_config(text, "w.yaml")
    assert cfg is None and len(errors) == 1
    assert str(errors[0]).startswith("w.yaml:3: watchdog.timeout: 0.05 s is shorter than one "
                                     "tick (1 s at scheduler.rate_hz 1)")
    assert parse_config(text.replace("rate_hz: 1}", "rate_hz: 20}"), "w.yaml")[1] == []
