"""The simulator's hot path, compiled, used only while it matches the sources.

A simulated mission runs the scheduler, the emulators, the physics and the autonomy's per-sample
maths a hundred times a simulated second, and in plain Python that caps it near 25x real time.
`scripts/build_accel.py` (run by `make`) compiles those modules with mypyc into `build/accel/`
beside a manifest of each source's SHA-256. `install()`, called when `ramp` is imported, puts a
finder first on `sys.meta_path` that serves the compiled modules, but only when every source
still matches the manifest: edit one file and the whole set falls back to the sources (the
compiled modules call each other directly, so half a set would run old code). `RAMP_ACCEL=0`
turns it off. The compiled code computes what the sources compute (mission summaries were
compared bit for bit); only the speed differs.

A leaf of `ramp.common`: it imports nothing of RAMP, and never imports the modules it serves.
"""

from __future__ import annotations

import hashlib
import importlib.abc
import importlib.machinery
import importlib.util
import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

#: The repository root of an editable install (ramp/common/accel.py -> the root).
ROOT = Path(__file__).resolve().parents[2]
#: Where scripts/build_accel.py writes the extension modules and the manifest.
BUILD_DIR = ROOT / "build" / "accel"
MANIFEST = "manifest.json"


@dataclass
class AccelStatus:
    """Whether the compiled modules are in use, and why not when they are not."""

    active: bool = False
    reason: str = "not installed"
    modules: list[str] = field(default_factory=list)


_status = AccelStatus()


def status() -> AccelStatus:
    """What `install()` decided (the mission summary and `python -m bench` report it)."""
    return _status


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def check(build_dir: Path = BUILD_DIR, root: Path = ROOT) -> tuple[dict[str, Path], str]:
    """The compiled modules by name when the build matches the sources, else ({}, why not)."""
    try:
        manifest = json.loads((build_dir / MANIFEST).read_text())
    except FileNotFoundError:
        return {}, f"not built ({build_dir / MANIFEST} is missing; run make)"
    except (OSError, ValueError) as exc:
        return {}, f"unreadable manifest {build_dir / MANIFEST}: {exc}"
    try:
        if manifest.get("cache_tag") != sys.implementation.cache_tag:
            return {}, (f"built for {manifest.get('cache_tag')}, "
                        f"this is {sys.implementation.cache_tag}")
        files: dict[str, Path] = {}
        for name, entry in manifest.get("modules", {}).items():
            source = root / entry["source"]
            try:
                same = _sha256(source) == entry["sha256"]
            except OSError:
                same = False
            if not same:
                return {}, f"{entry['source']} changed since the build (run make)"
            files[name] = build_dir / entry["extension"]
        for name, ext in manifest.get("runtime", {}).items():
            files[name] = build_dir / ext
    except (AttributeError, KeyError, TypeError) as exc:  # valid JSON, not a manifest
        return {}, f"unreadable manifest {build_dir / MANIFEST}: no {exc} where expected"
    missing = [str(path) for path in files.values() if not path.is_file()]
    if missing:
        return {}, f"the build is incomplete: {missing[0]} is missing (run make)"
    return files, ""


class CompiledFinder(importlib.abc.MetaPathFinder):
    """Finds the compiled build of the modules it was given, and nothing else."""

    def __init__(self, files: dict[str, Path]) -> None:
        self.files = files

    def find_spec(self, fullname: str, path: object = None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        file = self.files.get(fullname)
        if file is None:
            return None
        loader = importlib.machinery.ExtensionFileLoader(fullname, str(file))
        return importlib.util.spec_from_file_location(fullname, file, loader=loader)


def install() -> AccelStatus:
    """Serve the compiled modules from now on when the build is current (idempotent)."""
    global _status
    if any(isinstance(finder, CompiledFinder) for finder in sys.meta_path):
        return _status
    if os.environ.get("RAMP_ACCEL", "1") == "0":
        _status = AccelStatus(False, "turned off (RAMP_ACCEL=0)")
        return _status
    files, why = check()
    if not files:
        _status = AccelStatus(False, why)
        return _status
    sys.meta_path.insert(0, CompiledFinder(files))
    modules = sorted(name for name in files if "." in name)
    _status = AccelStatus(True, "", modules)
    return _status
