"""scripts/ramp.service and scripts/install-service.sh: keys, systemd's own verdict, dry runs."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
UNIT = REPO / "scripts" / "ramp.service"
INSTALL = REPO / "scripts" / "install-service.sh"


def parse_unit(text: str) -> dict[str, dict[str, list[str]]]:
    """Sections -> key -> every value given (systemd allows a key more than once)."""
    sections: dict[str, dict[str, list[str]]] = {}
    current: dict[str, list[str]] | None = None
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        if line.startswith("[") and line.endswith("]"):
            current = sections.setdefault(line[1:-1], {})
            continue
        assert current is not None, f"line {number}: key outside a section: {raw!r}"
        assert "=" in line, f"line {number}: not key=value: {raw!r}"
        key, value = line.split("=", 1)
        current.setdefault(key.strip(), []).append(value.strip())
    return sections


@pytest.fixture(scope="module")
def unit() -> dict[str, dict[str, list[str]]]:
    return parse_unit(UNIT.read_text())


def one(unit: dict[str, dict[str, list[str]]], section: str, key: str) -> str:
    values = unit[section].get(key)
    assert values is not None, f"[{section}] has no {key}="
    assert len(values) == 1, f"[{section}] sets {key}= {len(values)} times"
    return values[0]


@pytest.mark.parametrize(("key", "value"), [
    ("Type", "notify"),
    ("NotifyAccess", "main"),
    ("WatchdogSec", "2"),
    ("Restart", "on-failure"),
    ("RestartSec", "1"),
    ("TimeoutStopSec", "5"),
    ("KillSignal", "SIGTERM"),
    ("User", "ramp"),
    ("Group", "ramp"),
    ("WorkingDirectory", "/opt/ramp"),
    ("ExecStart", "/opt/ramp/.venv/bin/ramp run --config /etc/ramp/ramp.yaml"),
    ("NoNewPrivileges", "yes"),
    ("ProtectSystem", "strict"),
    ("ProtectHome", "yes"),
    ("PrivateTmp", "yes"),
    ("ProtectKernelTunables", "yes"),
    ("ProtectControlGroups", "yes"),
    ("DevicePolicy", "auto"),
    ("RestartPreventExitStatus", "2"),
    ("CPUSchedulingPolicy", "fifo"),
    ("CPUSchedulingPriority", "20"),
    ("LimitRTPRIO", "20"),
    ("LimitNOFILE", "8192"),
    ("StateDirectory", "ramp"),
    ("StateDirectoryMode", "0750"),
])
def test_service_key(unit: dict[str, dict[str, list[str]]], key: str, value: str) -> None:
    assert one(unit, "Service", key) == value


def test_groups_address_families_and_no_private_devices(
        unit: dict[str, dict[str, list[str]]]) -> None:
    assert set(one(unit, "Service", "SupplementaryGroups").split()) == {"dialout", "plugdev"}
    assert set(one(unit, "Service", "RestrictAddressFamilies").split()) == {
        "AF_INET", "AF_INET6", "AF_UNIX", "AF_CAN", "AF_NETLINK"}
    # PrivateDevices would hide /dev/ttyUSB*; DeviceAllow would whitelist and so hide the rest.
    for key in ("PrivateDevices", "DeviceAllow", "ProtectKernelModules"):
        assert key not in unit["Service"], f"{key}= would cut the service off its devices"
    assert one(unit, "Install", "WantedBy") == "multi-user.target"


def test_scheduling_priority_fits_the_rtprio_limit(
        unit: dict[str, dict[str, list[str]]]) -> None:
    assert 1 <= int(one(unit, "Service", "CPUSchedulingPriority")) <= int(
        one(unit, "Service", "LimitRTPRIO")) <= 99


def test_every_setting_is_commented() -> None:
    """Each group of keys in [Service] follows a comment saying why."""
    lines = UNIT.read_text().splitlines()
    start = lines.index("[Service]")
    end = lines.index("[Install]")
    uncommented = []
    for i in range(start + 1, end):
        line = lines[i]
        if not line or line.startswith("#"):
            continue
        j = i - 1
        while j > start and lines[j] and not lines[j].startswith("#"):
            j -= 1
        if j <= start or not lines[j].startswith("#"):
            uncommented.append(line)
    assert uncommented == []


def _verify(path: Path) -> list[str]:
    """systemd-analyze's warnings about `path` (it exits 0 on unknown keys, so read them)."""
    proc = subprocess.run(["systemd-analyze", "verify", str(path)], capture_output=True,
                          text=True, timeout=30, env={**os.environ, "SYSTEMD_LOG_COLOR": "0"})
    lines = (proc.stdout + proc.stderr).splitlines()
    mine = [line for line in lines if str(path) in line or path.name in line]
    if proc.returncode != 0:
        mine.append(f"exit {proc.returncode}: {proc.stderr.strip()}")
    return mine


@pytest.mark.skipif(shutil.which("systemd-analyze") is None,
                    reason="systemd-analyze is not installed (Debian: apt-get install systemd)")
def test_systemd_analyze_verify_accepts_the_unit(tmp_path: Path) -> None:
    # verify checks that ExecStart exists: point it at one, keep everything else.
    text = re.sub(r"(?m)^ExecStart=\S+", f"ExecStart={shutil.which('true') or '/bin/true'}",
                  UNIT.read_text())
    good = tmp_path / "ramp.service"
    good.write_text(text)
    assert _verify(good) == []
    # The check can fail: a misspelt key and a bad value are reported.
    broken = tmp_path / "broken" / "ramp.service"
    broken.parent.mkdir()
    broken.write_text(text.replace("Type=notify", "Type=notfy").replace(
        "NotifyAccess=main", "NotifyAcess=main"))
    complaints = "\n".join(_verify(broken))
    assert "NotifyAcess" in complaints and "notfy" in complaints


# --------------------------------------------------------------------------- install script


def install(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    # PYTHON: the interpreter that makes the certificates under --root (this one: it has
    # RAMP's dependencies; the target's own venv does it on a live install).
    return subprocess.run(["bash", str(INSTALL), *args], capture_output=True, text=True,
                          timeout=60, env={**os.environ, "PYTHON": sys.executable,
                                           **(env or {})})


def test_install_script_parses_and_is_strict() -> None:
    proc = subprocess.run(["bash", "-n", str(INSTALL)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    text = INSTALL.read_text()
    assert text.startswith("#!/usr/bin/env bash\n")
    assert "\nset -euo pipefail\n" in text
    assert os.access(INSTALL, os.X_OK)


@pytest.mark.skipif(shutil.which("shellcheck") is None, reason="shellcheck is not installed")
def test_install_script_passes_shellcheck() -> None:
    proc = subprocess.run(["shellcheck", str(INSTALL)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout


def test_dry_run_on_the_live_system_prints_every_step_and_needs_no_root() -> None:
    proc = install("--dry-run")
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert re.search(r"useradd --system .*--groups dialout,plugdev ramp|"
                     r"usermod --append --groups dialout,plugdev ramp", out)
    assert "-m venv /opt/ramp/.venv" in out or "pip install" in out
    assert "pip install --quiet --upgrade /opt/ramp[phidget]" in out
    assert 'ATTRS{idVendor}=="06c2"' in out and 'GROUP="plugdev"' in out
    assert "/etc/systemd/system/ramp.service" in out
    assert "systemctl daemon-reload" in out
    assert "systemctl enable --now ramp.service" in out
    assert out.index("daemon-reload") < out.index("enable --now")


def test_dry_run_into_a_root_changes_nothing(tmp_path: Path) -> None:
    proc = install("--dry-run", "--root", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert f"grep -v '^server:' {REPO}/ramp.yaml > {tmp_path}/etc/ramp/ramp.yaml" in proc.stdout
    assert f"certs init {tmp_path}/etc/ramp/certs --host 127.0.0.1" in proc.stdout
    assert f"write {tmp_path}/etc/udev/rules.d/60-ramp-phidgets.rules" in proc.stdout
    assert "systemctl enable" not in proc.stdout.replace(
        "skipped with --root: systemctl daemon-reload, enable --now", "")
    assert list(tmp_path.iterdir()) == []


def test_install_into_a_root_is_idempotent_and_keeps_the_config(tmp_path: Path) -> None:
    first = install("--root", str(tmp_path))
    assert first.returncode == 0, first.stderr
    app = tmp_path / "opt" / "ramp"
    assert (app / "ramp" / "shell" / "cli.py").is_file()
    assert (app / "scripts" / "ramp.service").is_file()
    assert not (app / ".git").exists() and not (app / ".venv").exists()
    unit = tmp_path / "etc" / "systemd" / "system" / "ramp.service"
    assert unit.read_text() == UNIT.read_text()
    rule = (tmp_path / "etc" / "udev" / "rules.d" / "60-ramp-phidgets.rules").read_text()
    assert 'SUBSYSTEM=="usb", ATTRS{idVendor}=="06c2", MODE="0660", GROUP="plugdev"' in rule
    config = tmp_path / "etc" / "ramp" / "ramp.yaml"
    wiring = "".join(line for line in (REPO / "ramp.yaml").read_text().splitlines(True)
                     if not line.startswith("server:"))
    assert config.read_text() == (wiring + "\n"
                                  + (REPO / "scripts" / "ramp-service.yaml").read_text())
    certs = tmp_path / "etc" / "ramp" / "certs"
    assert {p.name for p in certs.iterdir()} == {"ca.crt", "ca.key", "robot.crt", "robot.key"}
    assert (certs / "robot.key").stat().st_mode & 0o077 == 0
    config.write_text("# edited on the robot\n")
    second = install("--root", str(tmp_path))
    assert second.returncode == 0, second.stderr
    assert "exists: kept as it is" in second.stdout
    assert config.read_text() == "# edited on the robot\n"


def test_the_installed_config_records_into_the_units_state_directory(
        tmp_path: Path, unit: dict[str, dict[str, list[str]]]) -> None:
    """The service's config turns the flight recorder on, in a directory the unit lets it
    write (ProtectSystem=strict leaves only StateDirectory= writable), and passes
    `ramp check`."""
    from ramp.config import check_config

    assert install("--root", str(tmp_path)).returncode == 0
    config, errors = check_config(tmp_path / "etc" / "ramp" / "ramp.yaml")
    assert errors == [] and config is not None and config.recorder is not None
    state = Path("/var/lib") / one(unit, "Service", "StateDirectory")
    assert Path(config.recorder.dir).is_relative_to(state)
    assert config.recorder.max_mb * config.recorder.keep <= 4000  # a few GB of an SD card
    assert set(config.modules) == {"base", "ble"}  # the robot's wiring, unchanged
    # the secure set-up (SPEC 13): every interface, mutual TLS, roles; loopback operators
    assert config.server.host == "0.0.0.0" and config.server.tls is not None
    assert config.access.configured and config.access.local == "operator"
    dry = install("--dry-run", "--root", str(tmp_path / "dry"))
    assert f"cat {REPO}/scripts/ramp-service.yaml >> {tmp_path}/dry/etc/ramp/ramp.yaml" \
        in dry.stdout


def test_unknown_option_is_refused() -> None:
    proc = install("--frobnicate")
    assert proc.returncode == 2
    assert "unknown option --frobnicate" in proc.stderr
