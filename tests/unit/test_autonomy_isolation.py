"""The autonomy stays removable (SPEC 6, issue "Autonomy hardware"): it imports none of the
backend's layers, and nothing in the backend imports it.

Checked twice: in the source (every import statement and every `importlib.import_module`
literal, wherever it sits, so a lazy import inside a function counts too), and at run time in
a fresh interpreter (what importing really pulls in). The simulation glue (`ramp/simulation/`)
is the one place allowed to see both, and only lazily, so `ramp` itself starts without it.
`tests/hil_sim/test_backend_without_autonomy.py` deletes the package and runs the backend.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
RAMP = REPO / "ramp"

#: What the autonomy must never import (SPEC 6; the brief's list), nor the simulator.
BACKEND = ("ramp.layers", "ramp.modules", "ramp.hal", "ramp.runtime", "ramp.config",
           "ramp.simulation.backplane", "firmware_like")
AUTONOMY = ("ramp.autonomy", "ramp.statemachine")
#: Packages allowed to import the autonomy: itself, its state machine, the simulation glue.
GLUE = ("autonomy", "statemachine", "simulation")


def imports_of(path: Path) -> set[str]:
    """Every module `path` imports, at any depth of its code."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = ".".join(path.relative_to(REPO).with_suffix("").parts[:-1])
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            found.add(module)
            found.update(f"{module}.{alias.name}" for alias in node.names)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr == "import_module" and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            found.add(node.args[0].value)
    return found


def hits(modules: set[str], prefixes: tuple[str, ...]) -> list[str]:
    return sorted(m for m in modules
                  if any(m == p or m.startswith(p + ".") for p in prefixes))


def test_the_autonomy_imports_nothing_from_the_backend_or_the_simulator() -> None:
    files = [p for d in AUTONOMY if (RAMP / d.split(".")[1]).is_dir()
             for p in (RAMP / d.split(".")[1]).rglob("*.py")]
    assert len(files) > 20
    bad = {str(p.relative_to(REPO)): hits(imports_of(p), BACKEND) for p in files}
    assert {k: v for k, v in bad.items() if v} == {}


def test_nothing_in_the_backend_imports_the_autonomy() -> None:
    files = [p for p in RAMP.rglob("*.py")
             if p.relative_to(RAMP).parts[0] not in GLUE]
    assert any(p.name == "supervisor.py" for p in files)
    bad = {str(p.relative_to(REPO)): hits(imports_of(p), AUTONOMY) for p in files}
    assert {k: v for k, v in bad.items() if v} == {}


def test_the_simulation_glue_reaches_the_autonomy_only_from_inside_functions() -> None:
    for path in (RAMP / "simulation").glob("commands*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        top = set()
        for node in tree.body:
            if isinstance(node, ast.Import):
                top.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                top.add(node.module or "")
        assert hits(top, AUTONOMY) == [], path


AUTONOMY_ALONE = """
import importlib, json, pkgutil, sys
import ramp.autonomy
for info in pkgutil.walk_packages(ramp.autonomy.__path__, "ramp.autonomy."):
    importlib.import_module(info.name)
print(json.dumps(sorted(sys.modules)))
"""

BACKEND_ALONE = """
import argparse, json, sys
from ramp.cli import main
assert main(["check", "ramp.yaml"]) == 0
import ramp.shell
from ramp.simulation.commands import add_sim_parser
add_sim_parser(argparse.ArgumentParser().add_subparsers())
print(json.dumps(sorted(sys.modules)))
"""


def loaded_by(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                         text=True, timeout=60, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_at_run_time_the_autonomy_loads_no_backend_module() -> None:
    loaded = loaded_by(AUTONOMY_ALONE)
    assert "ramp.autonomy.perception.ahrs" in loaded and "ramp.autonomy.mcp_link" in loaded
    assert hits(loaded, BACKEND) == []


def test_at_run_time_the_backend_and_its_commands_load_no_autonomy_module() -> None:
    loaded = loaded_by(BACKEND_ALONE)
    assert "ramp.config" in loaded and "ramp.shell" in loaded
    assert hits(loaded, AUTONOMY) == []


def test_the_state_machine_does_not_import_the_autonomy_back() -> None:
    # The executive imports the machine; a machine importing the autonomy's planner made a
    # cycle (ramp.statemachine <-> ramp.autonomy). Its context names planning types for
    # type checking only, so loading the machine loads nothing of the autonomy.
    loaded = loaded_by("import json, sys\nimport ramp.statemachine\n"
                       "print(json.dumps(sorted(sys.modules)))")
    assert "ramp.statemachine.mission" in loaded
    assert hits(loaded, ("ramp.autonomy",)) == []
    for path in (RAMP / "statemachine").rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in tree.body:  # module level, outside `if TYPE_CHECKING:`
            if isinstance(node, ast.ImportFrom | ast.Import):
                names = [node.module or ""] if isinstance(node, ast.ImportFrom) else [
                    a.name for a in node.names]
                assert hits(set(names), ("ramp.autonomy",)) == [], path
