"""`ramp-fleet-agent`'s command line: config mistakes exit 2 naming file:line: key, and an
agent whose backend is not there says so in a state that still validates."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from ramp.fleet.broker import LocalBroker, free_port
from tests.fleet.schemas import validate
from tests.fleet_fixtures import Collector, start_agent
from tests.harness import REPO, stop_process


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "ramp.fleet.cli", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=30)


def test_config_mistakes_exit_2_at_their_line(tmp_path: Path) -> None:
    cfg = tmp_path / "r.yaml"
    cfg.write_text("server: {port: 5577}\nfleet:\n  serial: a b\n  broker: nohost\n")
    out = run_cli("--config", str(cfg))
    assert out.returncode == 2
    assert f"{cfg}:3: fleet.serial" in out.stderr and f"{cfg}:4: fleet.broker" in out.stderr
    out = run_cli("--config", str(cfg), "--serial", "ok", "--broker", "h:1", "--backend", "x:y")
    assert out.returncode == 2 and "--backend" in out.stderr
    out = run_cli("--config", str(tmp_path / "missing.yaml"))
    assert out.returncode == 2 and "missing.yaml" in out.stderr


def test_an_unreachable_backend_is_a_fatal_error_in_state(mosquitto: LocalBroker,
                                                          tmp_path: Path) -> None:
    col = Collector(mosquitto.host, mosquitto.port, ["uagv/v2/RAMP/lost/#"])
    agent = start_agent("ramp.yaml", f"127.0.0.1:{free_port()}", mosquitto.address, "lost",
                        str(tmp_path))
    try:
        state = col.wait_for("/state", lambda m: any(
            e["errorType"] == "backendUnreachable" for e in m["errors"]))
        assert not state["driving"]
        validate("state", state)
    finally:
        stop_process(agent)
        col.close()
