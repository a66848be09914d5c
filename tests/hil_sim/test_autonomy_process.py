"""`ramp-autonomy --backend` and `ramp sim mission --realtime` as real processes on the wall
clock, against a backend over TCP.

- `ramp-autonomy` on a machine without its sensors (no Phidget boards, no LIDAR at the
  configured address): it connects to `ramp run --sim`, acquires control as `autonomy`, and
  waits in Initial Localization for sensors that never come (saying why); SIGTERM stops the
  robot and ends it with status 0, and control is free again.
- `ramp sim mission --realtime --port 0` serves MCP for an operator: `robot.get` shows the
  autonomy holding control while the mission runs.

About 12 s of wall time together.
"""

from __future__ import annotations

import os
import re
import select
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.harness import REPO, ask_line, end_process, start_ramp

pytestmark = pytest.mark.timeout(90)


def wait_for(predicate: object, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():  # type: ignore[operator]
            return True
        time.sleep(0.1)
    return False


def test_ramp_autonomy_takes_control_waits_for_its_sensors_and_stops_on_sigterm(
        tmp_path: Path) -> None:
    config = tmp_path / "autonomy.yaml"
    text = (REPO / "autonomy.yaml").read_text()
    text = text.replace("host: 192.168.0.10", "host: 127.0.0.1").replace("port: 10940",
                                                                          "port: 9")
    config.write_text(text)
    backend, host, port = start_ramp(["--sim", "--port", "0"])
    auto = subprocess.Popen(
        [sys.executable, "-m", "ramp.autonomy.cli", "--backend", f"{host}:{port}",
         "--config", str(config)], cwd=REPO, text=True, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    sock = socket.create_connection((host, port), timeout=5)
    try:
        def owner() -> str:
            line = ask_line(sock, "robot:robot.get=()")
            m = re.search(r"robot:control\.owner=\((\w+)\)", line)
            return m.group(1) if m else ""

        assert wait_for(lambda: owner() == "autonomy", 15.0)
        time.sleep(1.0)
        _out, err = end_process(auto)
        assert auto.returncode == 0, err
        assert "initial_localization" in err
        assert "SIGTERM: stopping the robot" in err
        assert wait_for(lambda: owner() == "none", 5.0)
    finally:
        sock.close()
        if auto.poll() is None:
            auto.kill()
        backend.send_signal(signal.SIGTERM)
        backend.communicate(timeout=10)


def test_ramp_autonomy_without_a_backend_says_how_to_use_it() -> None:
    out = subprocess.run([sys.executable, "-m", "ramp.autonomy.cli"], cwd=REPO,
                         capture_output=True, text=True, timeout=30)
    assert out.returncode == 2
    assert "--backend HOST:PORT" in out.stderr and "ramp-autonomy check FILE" in out.stderr


def test_a_realtime_mission_serves_mcp_for_an_operator_to_watch() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "ramp.cli", "sim", "mission", "--realtime", "--port", "0",
         "--duration", "6"], cwd=REPO, text=True, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert proc.stdout is not None
    try:
        host = port = None
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and port is None:
            r, _, _ = select.select([proc.stdout], [], [], 0.5)
            if r:
                m = re.search(r"MCP on ([\d.]+):(\d+)", proc.stdout.readline())
                if m:
                    host, port = m.group(1), int(m.group(2))
        assert port is not None, "no MCP address printed"
        sock = socket.create_connection((host, port), timeout=5)
        try:
            def owner() -> str:
                line = ask_line(sock, "robot:robot.get=()")
                m = re.search(r"robot:control\.owner=\((\w+)\)", line)
                return m.group(1) if m else ""

            assert wait_for(lambda: owner() == "autonomy", 5.0)
        finally:
            sock.close()
        out, _err = proc.communicate(timeout=30)
        assert "acquire_control -> initial_localization" in out
        assert proc.returncode in (0, 1)  # a 6 s run does not qualify
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
