"""Compile the simulator's hot path with mypyc into build/accel/ (see ramp/common/accel.py).

Run by `make` after the editable install; `python scripts/build_accel.py` by hand. mypyc turns
type-annotated modules into C extensions that compute the same thing faster; the list below
is what a simulated mission spends its time in (profile: docs/developing/benchmarks-mission.md).
A module joins the list only if its tests pass compiled and mission summaries stay bit for bit
the same. Without a C compiler the build fails and RAMP runs the sources, only slower.
"""

from __future__ import annotations

import ast
import hashlib
import json
import os
import shutil
import sys
import sysconfig
from importlib.machinery import EXTENSION_SUFFIXES as _SUFFIXES
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "build" / "accel"
WORK = ROOT / "build" / "accel-work"
GROUP = "ramp_accel"
EXTENSION_SUFFIXES = tuple(_SUFFIXES)

#: The compiled modules, by path from the repository root: the simulator's physics and
#: emulators and the autonomy's per-sample maths, nothing on the robot's safety path. The
#: backend (the scheduler, the MCP server, the drivers, the bus manager, the interlocks, the
#: base's drive algorithm) and the autonomy's link to it (the executive's robot and driver,
#: the TCP client) run from their sources everywhere: the robot's service install runs the
#: sources, so that is the form the tests must run (compiled code differs: annotations
#: enforced, classes closed). tests/unit/test_accel.py holds the list to that rule.
#: Also left out, and why (a compiled class is fixed: its methods cannot be replaced on an
#: instance nor its base be an interpreted class): the plugin API's base classes and the
#: drivers built on them in Python (ramp/autonomy/hal/sim.py, simlink.py); the Hokuyo driver
#: (its abstract base fails at construction); ramp/simulation/rig.py (finds files by
#: `__file__`); the planner's grid search (ramp/autonomy/planning/astar.py: compiled, it
#: refused a cell of numpy integers and a blocked map that is not bool, which its sources
#: take) and the pose tracker (tests hand it duck-typed gyros).
MODULES = [
    "firmware_like/imu.py",
    "firmware_like/marte.py",
    "firmware_like/arena_floor.py",
    "firmware_like/servo.py",
    "ramp/autonomy/perception/ahrs.py",
    "ramp/autonomy/perception/gimbal.py",
    "ramp/autonomy/odometry.py",
    "ramp/autonomy/mount.py",
    "firmware_like/sabertooth.py",
    "firmware_like/hokuyo.py",
    "firmware_like/pty_link.py",
    "firmware_like/bucket_ladder.py",
    "firmware_like/world.py",
    "ramp/simulation/backplane.py",
    "ramp/autonomy/perception/scans.py",
    "ramp/autonomy/planning/follower.py",
    "ramp/autonomy/planning/geometry.py",
]

#: The packages whose modules a compiled module may read constants from (mypyc inlines a
#: `Final` of a module it does not compile): their sources are hashed too, see `inputs`.
FIRST_PARTY = ("ramp", "firmware_like")


def module_name(path: str) -> str:
    return path.removesuffix(".py").removesuffix("/__init__").replace("/", ".")


def _source_of(name: str, root: Path) -> str | None:
    """The first-party source file of module `name` (a path from `root`), or None."""
    if name.split(".")[0] not in FIRST_PARTY:
        return None
    base = name.replace(".", "/")
    for rel in (f"{base}.py", f"{base}/__init__.py"):
        if (root / rel).is_file():
            return rel
    return None


def _imported(rel: str, root: Path) -> set[str]:
    """The module names `rel` imports anywhere in its text (TYPE_CHECKING and function bodies
    included: mypy reads them all), with the packages each one runs on the way."""
    tree = ast.parse((root / rel).read_text(), rel)
    package = module_name(rel) if rel.endswith("__init__.py") else module_name(rel).rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                anchor = ".".join(parts[:len(parts) - node.level + 1])
                base = f"{anchor}.{node.module}" if node.module else anchor
            else:
                base = node.module or ""
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)  # a submodule?
    out: set[str] = set()
    for name in names:
        parts = name.split(".")
        out.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
    return out


def inputs(modules: list[str], root: Path = ROOT) -> list[str]:
    """Every first-party source the compiled modules read, transitively: the modules
    themselves and all they import. mypyc copies a `Final` constant of a module it does not
    compile into the compiled code (the Sabertooth emulator's timings, the arena's sizes), so a
    change to any of these leaves the build stale (ramp/common/accel.py checks them all)."""
    seen: set[str] = set()
    todo = list(modules)
    while todo:
        rel = todo.pop()
        if rel in seen:
            continue
        seen.add(rel)
        for name in _imported(rel, root):
            found = _source_of(name, root)
            if found is not None and found not in seen:
                todo.append(found)
    return sorted(seen)


def main() -> int:
    if sys.argv[1:] == ["--list"]:  # the Makefile's dependencies: what the build reads
        sys.stdout.write(" ".join(inputs(MODULES)) + "\n")
        return 0
    from mypyc.build import mypycify  # the dev extra's mypy ships mypyc
    from setuptools import setup

    os.chdir(ROOT)  # mypyc names the modules by their paths from here
    shutil.rmtree(OUT, ignore_errors=True)
    shutil.rmtree(WORK, ignore_errors=True)
    # Hashed before compiling: a source edited during the build no longer matches the manifest.
    sources = {p: hashlib.sha256((ROOT / p).read_bytes()).hexdigest()
               for p in inputs(MODULES)}
    extensions = mypycify(MODULES, opt_level="3", group_name=GROUP, multi_file=True,
                          target_dir=str(WORK / "c"))
    setup(name="ramp-accel", ext_modules=extensions, script_name="build_accel.py",
          script_args=["-q", "build_ext", "--build-lib", str(OUT),
                       "--build-temp", str(WORK / "obj"), "--parallel", str(os.cpu_count() or 1)])
    built = [p.relative_to(OUT).as_posix() for p in OUT.rglob("*") if p.is_file()]

    def extension_of(name: str) -> str:
        stem = name.replace(".", "/") + "."
        for rel in built:
            if rel.startswith(stem) and rel.endswith(EXTENSION_SUFFIXES):
                return rel
        raise SystemExit(f"build_accel: no extension was built for {name}")

    manifest = {
        "cache_tag": sys.implementation.cache_tag,
        "platform": sysconfig.get_platform(),
        "modules": {module_name(p): {"source": p, "sha256": sources[p],
                                     "extension": extension_of(module_name(p))}
                    for p in MODULES},
        "runtime": {f"{GROUP}__mypyc": extension_of(f"{GROUP}__mypyc")},
        # What the compiled code may have copied from: a change here makes the build stale.
        "inputs": {p: sources[p] for p in sorted(sources) if p not in MODULES},
    }
    (OUT / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    sys.stdout.write(f"build_accel: {len(MODULES)} modules compiled into {OUT.relative_to(ROOT)}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
