"""The import contract in `pyproject.toml` (`make lint` runs `lint-imports`) catches what it
is there for: a copy of the tree passes it, and the same copy with five bad imports fails
each of its contracts, by name. Without this, a contract with a typo in a module name
(or one that matches nothing) would pass for ever and check nothing.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")

#: Python only ignores an editable install's finder if told to (see
#: tests/hil_sim/test_backend_without_autonomy.py): the copy must be what grimp reads.
FORGET_EDITABLE = """
import sys
sys.meta_path[:] = [f for f in sys.meta_path
                    if not getattr(f, "__module__", "").startswith("__editable__")]
sys.path_hooks[:] = [h for h in sys.path_hooks
                     if not getattr(h, "__module__", "").startswith("__editable__")]
sys.path_importer_cache.clear()
"""

#: Bad imports, at least one per contract: (file, line appended, the contract it breaks). The
#: second breaks the layers through the recorder: it may import only the shared core.
VIOLATIONS = [
    ("ramp/hal/interfaces.py", "import ramp.layers.robot_distribution",
     "Backend layers (thesis figure 4.3): nothing imports upward"),
    ("ramp/recorder/writer.py", "import ramp.runtime.supervisor",
     "Backend layers (thesis figure 4.3): nothing imports upward"),
    ("ramp/layers/functional/motor.py", "import firmware_like.marte",
     "Only the simulation entry points (ramp.simulation) import firmware_like"),
    ("ramp/autonomy/odometry.py", "import ramp.hal.sabertooth",
     "The MCP clients (autonomy, teleop console, shell) never import the backend"),
    ("ramp/runtime/supervisor.py", "import ramp.teleop.console",
     "The backend never imports the autonomy or the teleop console"),
    # A package's own __init__ is held to its contract too, not only its submodules.
    ("ramp/statemachine/__init__.py", "import ramp.runtime.build",
     "The MCP clients (autonomy, teleop console, shell) never import the backend"),
    ("ramp/recorder/__init__.py", "import ramp.simulation.backplane",
     "The backend reaches firmware_like only through ramp.simulation, even indirectly"),
    # The shared leaf stays a leaf, and the emulators reach RAMP only through it.
    ("ramp/common/hostport.py", "import ramp.errors",
     "ramp.common is a leaf: it imports nothing of RAMP or of the emulators"),
    ("firmware_like/arena.py", "import ramp.clock",
     "firmware_like imports nothing of RAMP but the leaf ramp.common"),
    # The fleet (SPEC 14) is an MCP client like the autonomy, and apart from it.
    ("ramp/fleet/agent.py", "import ramp.runtime.supervisor",
     "The fleet (ramp.fleet) never imports the backend or the autonomy"),
    ("ramp/autonomy/arena.py", "import ramp.fleet.vda5050",
     "The backend, the autonomy and the console never import the fleet"),
]


def copy_tree(root: Path) -> Path:
    tree = root / "tree"
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", "static", "profiles")
    for name in ("ramp", "firmware_like"):
        shutil.copytree(REPO / name, tree / name, ignore=skip)
    shutil.copy(REPO / "pyproject.toml", tree / "pyproject.toml")
    (tree / "sitecustomize.py").write_text(FORGET_EDITABLE)
    return tree


def lint(tree: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run([str(LINT_IMPORTS), "--no-cache"], cwd=tree, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.skipif(not LINT_IMPORTS.exists(), reason="import-linter is not installed")
def test_the_contract_passes_the_tree_and_breaks_on_each_kind_of_bad_import(
        tmp_path: Path) -> None:
    tree = copy_tree(tmp_path)
    clean = lint(tree)
    assert clean.returncode == 0, clean.stdout[-3000:] + clean.stderr[-2000:]
    assert "9 kept, 0 broken" in clean.stdout

    for path, line, _ in VIOLATIONS:
        target = tree / path
        assert target.is_file(), path
        target.write_text(target.read_text() + f"\n{line}  # noqa\n")
    broken = lint(tree)
    assert broken.returncode == 1, broken.stdout[-3000:] + broken.stderr[-2000:]
    assert "0 kept, 9 broken" in broken.stdout, broken.stdout[-3000:]
    for path, line, contract in VIOLATIONS:
        assert f"{contract} BROKEN" in broken.stdout, contract
        imported = line.split()[1]
        importer = path.removesuffix(".py").removesuffix("/__init__").replace("/", ".")
        assert importer in broken.stdout and imported in broken.stdout, (importer, imported)
