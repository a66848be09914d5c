"""Broken and hostile config files end in `file:line: key: ...` and exit status 2, from
`ramp check` and `ramp run` alike; never a traceback, a hang or a megabyte of output."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from ramp.cli import main
from ramp.config import check_config, parse_config
from tests.harness import REPO

MODULES = "modules:\n  demo: {motor: {bus: io}, lamp: {bus: io}}\n"
GOOD = "server: {host: 127.0.0.1, port: 0}\nbuses:\n  io: {driver: sim}\n" + MODULES


def check(tmp_path: Path, content: str | bytes, capsys: pytest.CaptureFixture[str]
          ) -> tuple[int, list[str]]:
    """`ramp check` on a file holding `content`: (exit status, stderr lines)."""
    f = tmp_path / "ramp.yaml"
    if isinstance(content, str):
        f.write_text(content)
    else:
        f.write_bytes(content)
    code = main(["check", str(f)])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err.splitlines()


HOSTILE = {
    "a list as a key": ("server: {[a, b]: 1}\n" + MODULES,
                        "ramp.yaml:1: server: a key must be a name, not a list"),
    "a mapping as a key": ("? {x: 1}\n: 2\n" + MODULES,
                           "ramp.yaml:1: (top): a key must be a name, not a mapping"),
    "a Latin-1 byte in a comment": (b"# caf\xe9\n" + GOOD.encode(),
                                    "ramp.yaml:1: not UTF-8: byte 0xe9 at column 6"),
    "nesting 1,000 deep": ("server: " + "[" * 1000 + "]" * 1000 + "\n" + MODULES,
                           "ramp.yaml:1: not valid YAML: nested deeper than 32 levels"),
    "a NUL byte": ("buses:\n  io: {driver: sim}\n  x: 'a\x00b'\n" + MODULES,
                   "ramp.yaml:3: not valid YAML: character #x0000 is not allowed in YAML"),
    "a module name that is not ASCII": (GOOD.replace("demo:", "blé:"),
                                        "ramp.yaml:5: modules.blé: a module name is 1-32"),
    "a module name with MCP's own characters": (GOOD.replace("demo:", "'bl)e,x':"),
                                               "ramp.yaml:5: modules.bl)e,x: a module name"),
    "a module name of 33 characters": (GOOD.replace("demo:", "m" * 33 + ":"),
                                       "ramp.yaml:5: modules." + "m" * 33 + ": a module name"),
    "a host that looks like IPv4 and is not": (
        GOOD.replace("127.0.0.1", "999.1.1.1"),
        "ramp.yaml:1: server.host: '999.1.1.1' is not an IP address or host name"),
    "a host with a space": (GOOD.replace("127.0.0.1", "'my robot'"),
                            "ramp.yaml:1: server.host: 'my robot' is not an IP address"),
    "an empty file": ("", "ramp.yaml:1: modules: the file is empty"),
    "only comments": ("# nothing yet\n\n", "ramp.yaml:1: modules: the file is empty"),
    "no modules": ("buses:\n  io: {driver: sim}\n", "ramp.yaml:1: modules: no modules"),
    "a list where a bus name goes": (GOOD.replace("lamp: {bus: io}", "lamp: {bus: [io]}"),
                                     "ramp.yaml:5: modules.demo.lamp.bus: ['io'] is not a bus"),
    # Checked now, not retried once a second for ever by a bus that can never open.
    "an empty serial port": (GOOD.replace("{driver: sim}", "{driver: sim}\n  st: {driver: "
                                          "sabertooth, port: ''}"),
                             "ramp.yaml:4: buses.st.port: '' is not a serial device path"),
    "a blank CAN channel": (GOOD.replace("{driver: sim}", "{driver: sim}\n  c: {driver: can, "
                                         "channel: ' '}"),
                            "ramp.yaml:4: buses.c.channel: ' ' is not a CAN channel"),
    # A float key given an integer no float holds: OverflowError out of the check, once.
    "a 400-digit number where a float goes": (
        "scheduler: {rate_hz: " + "1" + "0" * 400 + "}\n" + GOOD,
        "ramp.yaml:1: scheduler.rate_hz: 1000000000"),
    "an unknown python-can interface": (
        GOOD.replace("{driver: sim}", "{driver: sim}\n  c: {driver: can, interface: nope, "
                     "channel: can0}"),
        "ramp.yaml:4: buses.c.interface: 'nope' is not a python-can interface name (one of "),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_file_is_a_located_error_and_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str) -> None:
    content, first = HOSTILE[case]
    code, lines = check(tmp_path, content, capsys)
    assert code == 2
    path = str(tmp_path / "ramp.yaml")
    errors = [line.replace(path, "ramp.yaml") for line in lines[:-1]]
    assert any(e.startswith(first) for e in errors), errors
    assert lines[-1].startswith(f"{path}: ") and "error" in lines[-1]


@pytest.mark.timeout(20)
def test_an_alias_bomb_is_refused_at_once_with_a_short_message(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """1.4 kB that expands to a billion values: 14 s, 800 MB and a 254 MB error line."""
    levels = ["  a0: &a0 [" + ", ".join(["lol"] * 9) + "]"]
    for i in range(1, 9):
        levels.append(f"  a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]")
    bomb = "buses:\n  io: {driver: sim}\n" + MODULES + "server:\n  host:\n" + "\n".join(
        "  " + line for line in levels) + "\n"
    assert len(bomb) < 1500
    t0 = time.monotonic()
    code, lines = check(tmp_path, bomb, capsys)
    assert time.monotonic() - t0 < 5
    assert code == 2
    assert "expands to more than 50000 values" in lines[0]
    assert sum(len(line) for line in lines) < 1000


def test_long_values_are_cut_short_in_messages(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    text = ("server: {host: 127.0.0.1, port: " + "9" * 4000 + "}\nbuses:\n  io: {driver: sim}\n"
            "modules:\n  demo:\n    " + "k" * 1000 + ": 1\n    motor: {bus: io}\n"
            "    lamp: {bus: '" + "x" * 100_000 + "'}\n")
    code, lines = check(tmp_path, text, capsys)
    assert code == 2
    assert len(lines) == 4 and all(len(line) < 600 for line in lines), [len(x) for x in lines]
    assert "characters) is not a TCP port (0-65535)" in lines[0]
    assert "modules.demo.kkkk" in lines[1] and "unknown device or setting" in lines[1]
    assert "(100002 characters) is not a bus (known: io)" in lines[2]


def test_a_number_python_cannot_read_is_an_error_at_its_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, lines = check(tmp_path, GOOD.replace("port: 0", "port: " + "9" * 100_000), capsys)
    assert code == 2
    assert lines[0].endswith("characters)") and ":1: not valid YAML: cannot read this value" \
        in lines[0] and len(lines[0]) < 400


def test_a_file_over_a_mebibyte_is_refused_before_parsing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, lines = check(tmp_path, GOOD + "#" * (1 << 20) + "\n", capsys)
    assert code == 2
    assert lines[0].endswith("larger than 1024 KiB; a config file is a few kB")


def test_yaml_merge_keys_work_and_explicit_keys_override() -> None:
    text = """\
buses:
  io: {driver: sim}
  m1: &motors {driver: sabertooth, port: /dev/ttyUSB0, baud: 19200}
  m2: {<<: *motors, port: /dev/ttyUSB1}
modules:
  demo: {motor: {bus: m2, address: 128, motor: 1}, lamp: {bus: io}}
"""
    cfg, errors = parse_config(text, "ramp.yaml")
    assert errors == []
    assert cfg is not None
    assert cfg.buses["m2"].params["port"] == "/dev/ttyUSB1"
    assert cfg.buses["m2"].params["baud"] == 19200
    assert cfg.buses["m1"].params["port"] == "/dev/ttyUSB0"
    _, errors = parse_config(text.replace("port: /dev/ttyUSB1}",
                                          "port: /dev/ttyUSB1, port: /dev/ttyUSB2}"))
    assert [str(e) for e in errors] == ["ramp.yaml:4: buses.m2.port: key given twice"]


def test_good_names_and_hosts_pass(tmp_path: Path) -> None:
    for host in ("0.0.0.0", "::1", "localhost", "robot-1.local", "fe80::1"):
        text = GOOD.replace("127.0.0.1", f"'{host}'").replace("demo: {", "Base_2: {type: demo, ")
        # off loopback only with TLS or an explicit opt-out (SPEC 13)
        text += "\naccess: {allow_anonymous: true}\n"
        f = tmp_path / "ok.yaml"
        f.write_text(text)
        cfg, errors = check_config(f)
        assert errors == [], (host, errors)
        assert cfg is not None and list(cfg.modules) == ["Base_2"]


@pytest.mark.parametrize("args", [["--port", "99999"], ["--port", "-1"], ["--port", "x"],
                                  ["--host", "999.1.1.1"]])
def test_bad_command_line_values_are_usage_errors(
        args: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["run", "--config", "ramp.yaml", *args])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert "is not a TCP port (0-65535)" in err or "is not an IP address or host name" in err


def test_ramp_run_agrees_with_ramp_check_on_exit_status_2(tmp_path: Path) -> None:
    """The same bad files through a real `ramp run`: the error lines and 2, no traceback."""
    for name, content in (("key.yaml", "server: {[a, b]: 1}\n" + MODULES),
                          ("latin1.yaml", b"# caf\xe9\n" + GOOD.encode()),
                          ("host.yaml", GOOD.replace("127.0.0.1", "999.1.1.1")),
                          ("empty.yaml", "")):
        f = tmp_path / name
        if isinstance(content, str):
            f.write_text(content)
        else:
            f.write_bytes(content)
        proc = subprocess.run([sys.executable, "-m", "ramp.cli", "run", "--config", str(f)],
                              cwd=REPO, text=True, capture_output=True, timeout=30)
        assert proc.returncode == 2, (name, proc.stderr)
        assert proc.stderr.startswith(f"{f}:"), (name, proc.stderr)
        assert "Traceback" not in proc.stderr
