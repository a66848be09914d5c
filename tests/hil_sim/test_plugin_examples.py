"""The plugin packages in examples/ as a team uses them (SPEC 10): built as wheels, found
through their entry points, run by `ramp run --sim` as a process and driven over MCP."""

from __future__ import annotations

import importlib.metadata as md
import re
import socket
import subprocess
import sys
import time
from subprocess import Popen

import pytest

from tests.harness import ask_line, end_process, start_ramp

PACKAGES = {"ramp-arm": ("arm",), "ramp-winch": ("winch",)}


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_each_example_package_is_installed_with_its_entry_points(package: str) -> None:
    """`make` installs them with pip, as a team installs a plugin (pip install -e DIR)."""
    dist = md.distribution(package)
    groups = {ep.group for ep in dist.entry_points}
    assert {"ramp.modules", "ramp.emulators"} <= groups
    for name in PACKAGES[package]:
        assert any(ep.name == name and ep.group == "ramp.modules" for ep in dist.entry_points)
        assert any(ep.name == f"module.{name}" for ep in dist.entry_points)


@pytest.mark.parametrize("config", ["winch.yaml", "winch-box.yaml"])
def test_the_guide_s_winch_runs_under_ramp_run_sim_and_stops_at_the_top(config: str) -> None:
    """winch.yaml: on RAMP's own drivers (the module guide); winch-box.yaml: on the plugin's
    winchbox driver (the driver guide)."""
    proc, host, port = start_ramp(["--sim", "--config", f"examples/ramp-winch/{config}",
                                   "--host", "127.0.0.1", "--port", "0"])
    try:
        with socket.create_connection((host, port), timeout=5) as s:
            assert ask_line(s, "robot:robot.modules=()") == "robot:robot.modules=(winch)"
            assert "winch:rope.function=(vel,int -100..100)" in ask_line(
                s, "winch:winch.describe=()")
            deadline = time.monotonic() + 30
            line = ""
            while time.monotonic() < deadline:
                # Asked again each time: a loaded machine's stalled tick stops every motor
                # (SPEC 2.2), and at the top the module itself refuses to wind further.
                assert ask_line(s, "winch:rope.vel=(100)") == ""
                line = ask_line(s, "winch:winch.get=()")
                if "top.press=(1)" in line:
                    break
                time.sleep(0.2)
            assert line == "winch:rope.vel=(0)winch:top.press=(1)"
    finally:
        _stop(proc)


def test_scout_runs_under_ramp_run_sim() -> None:
    proc, host, port = start_ramp(["--sim", "--config", "examples/robots/scout.yaml",
                                   "--host", "127.0.0.1", "--port", "0"])
    try:
        with socket.create_connection((host, port), timeout=5) as s:
            assert ask_line(s, "robot:robot.modules=()") == "robot:robot.modules=(base,arm)"
            assert ask_line(s, "arm:shoulder.pos=(45)") == ""
            assert ask_line(s, "base:base.drive=(30,0)") == ""
            assert "base:left_wheel.vel=(30)" in ask_line(s, "base:base.get=()")
        # ramp-shell on Scout, unchanged: a table from describe, errors as on MARTE.
        shell = [sys.executable, "-m", "ramp.shell", f"{host}:{port}"]
        out = subprocess.run([*shell, "-c", "arm:arm.get=()"], capture_output=True, text=True,
                             timeout=15)
        assert out.returncode == 0, out.stderr
        assert re.search(r"arm\s+shoulder\s+pos\s+-?\d+\.\d+ deg\n", out.stdout), out.stdout
        assert re.search(r"arm\s+arm\s+stowed\s+[01]\n", out.stdout), out.stdout
        bad = subprocess.run([*shell, "--raw", "-c", "arm:elbow.pos=(500)"],
                             capture_output=True, text=True, timeout=15)
        assert bad.returncode == 1
        assert bad.stdout.startswith("arm:elbow.error=(bad_params,pos takes one float in "
                                     "-120..120)")
    finally:
        _stop(proc)


def _stop(proc: Popen[str]) -> None:
    end_process(proc)
    assert proc.returncode == 0
