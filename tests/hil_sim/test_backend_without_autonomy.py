"""The backend with the autonomy deleted (SPEC 6, thesis requirement 2): a copy of the tree
without `ramp/autonomy` and `ramp/statemachine` still checks its config, runs the simulated
robot over TCP, opens the shell, draws `ramp sim lidar`, and passes a representative set of
the backend's own tests. `tests/unit/test_autonomy_isolation.py` checks the imports."""

from __future__ import annotations

import json
import os
import re
import select
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

#: Backend tests run in the copy: config, scheduler, MCP, modules, drivers, and whole
#: supervisors over TCP (about 10 s; the rest of the backend suite needs nothing else).
BACKEND_TESTS = [
    "tests/unit/test_config.py", "tests/unit/test_scheduler.py",
    "tests/unit/test_mcp_session.py", "tests/unit/test_base_module.py",
    "tests/unit/test_ble_module.py", "tests/unit/test_sabertooth_driver.py",
    "tests/unit/test_driver_registry.py", "tests/hil_sim/test_marte_sim.py",
    "tests/hil_sim/test_core_tcp.py", "tests/hil_sim/test_safety.py",
    "tests/hil_sim/test_wire.py",
]
SKIP = shutil.ignore_patterns(".git", ".venv", "__pycache__", ".mypy_cache", ".pytest_cache",
                              ".ruff_cache", ".hypothesis", "*.egg-info", "docs", "build")


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("without-autonomy") / "ramp-tree"
    shutil.copytree(REPO, root, ignore=SKIP)
    for gone in ("autonomy", "statemachine"):
        shutil.rmtree(root / "ramp" / gone, ignore_errors=True)
    assert not (root / "ramp" / "autonomy").exists()
    # An editable install of this repository would serve the deleted package from the
    # original tree (its finder sits on sys.meta_path): take it out in the copy's processes.
    (root / "sitecustomize.py").write_text(FORGET_EDITABLE)
    return root


FORGET_EDITABLE = """
import sys
sys.meta_path[:] = [f for f in sys.meta_path
                    if not getattr(f, "__module__", "").startswith("__editable__")]
sys.path_hooks[:] = [h for h in sys.path_hooks
                     if not getattr(h, "__module__", "").startswith("__editable__")]
sys.path_importer_cache.clear()
"""


def run(tree: Path, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run([sys.executable, *args], cwd=tree, env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_the_copy_is_what_python_imports(tree: Path) -> None:
    out = run(tree, "-c", "import ramp, firmware_like; print(ramp.__file__)")
    assert out.returncode == 0, out.stderr
    assert Path(out.stdout.strip()).is_relative_to(tree)
    gone = run(tree, "-c", "import ramp.autonomy")
    assert gone.returncode != 0 and "No module named 'ramp.autonomy'" in gone.stderr


def test_ramp_check_the_shell_and_ramp_sim_lidar_work_without_it(tree: Path) -> None:
    check = run(tree, "-m", "ramp.cli", "check", "ramp.yaml")
    assert check.returncode == 0 and "ramp.yaml: ok" in check.stdout, check.stderr
    shell = run(tree, "-c", "import ramp.shell, ramp.shell.complete, ramp.shell.render")
    assert shell.returncode == 0, shell.stderr
    lidar = run(tree, "-m", "ramp.cli", "sim", "lidar", "--seed", "1", "--at", "1.0,1.0,0",
                "--json")
    assert lidar.returncode == 0, lidar.stderr
    assert len(json.loads(lidar.stdout.splitlines()[-1])["ranges_mm"]) == 1081
    perceive = run(tree, "-m", "ramp.cli", "sim", "perceive", "--at", "1.0,1.0,0")
    assert perceive.returncode == 1 and "needs the autonomy package" in perceive.stderr


def test_ramp_run_sim_serves_the_robot_without_it(tree: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    proc = subprocess.Popen([sys.executable, "-m", "ramp.cli", "run", "--sim", "--port", "0",
                             "--host", "127.0.0.1"], cwd=tree, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert proc.stdout is not None
        address = None
        deadline = time.monotonic() + 30.0
        while address is None and time.monotonic() < deadline:
            ready, _, _ = select.select([proc.stdout], [], [], 0.5)
            if ready:
                m = re.match(r"ramp: ready on ([\d.]+):(\d+)", proc.stdout.readline())
                address = (m.group(1), int(m.group(2))) if m else None
        assert address is not None, "no ready line"
        with socket.create_connection(address, timeout=5.0) as sock:
            f = sock.makefile("rwb")
            for request, expect in (("robot:robot.modules=()", b"robot:robot.modules=(base,ble)"),
                                    ("base:base.drive=(30,0)", b""),
                                    ("base:base.get=()", b"base:lf_wheel.vel=(30)"),
                                    ("robot:robot.stop=()", b"")):
                f.write(request.encode() + b"\n")
                f.flush()
                assert f.readline().rstrip(b"\n").startswith(expect)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()


def test_the_backends_own_tests_pass_without_it(tree: Path) -> None:
    out = run(tree, "-m", "pytest", "-o", "addopts=", "-q", "-p", "no:cacheprovider",
              *BACKEND_TESTS, timeout=300.0)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    summary = out.stdout.strip().splitlines()[-1]
    assert re.search(r"\d{3} passed", summary) and "failed" not in summary, summary
