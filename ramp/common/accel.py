"""The simulator's hot path, compiled, used only while it matches the sources.

A simulated mission runs the emulators, the physics and the autonomy's per-sample maths a
hundred times a simulated second, and in plain Python that caps it near 25x real time.
`scripts/build_accel.py` (run by `make`) compiles those modules with mypyc into `build/accel/`
beside a manifest of the SHA-256 of each source and of every first-party module they import,
transitively (mypyc copies a `Final` constant of a module it does not compile into the
compiled code). Nothing on the robot's safety path is compiled: the backend runs its sources
in the tests as on the robot, whose service install has no build.

`install()`, called when `ramp` is imported, puts a finder first on `sys.meta_path` that serves
the compiled modules, but only when every hashed source still matches and the build is for
this interpreter and platform: otherwise the whole set falls back to the sources (the compiled
modules call each other directly, so half a set would run old code). A build that is there
but cannot be used (for another platform or ABI, an extension that fails to import) says so
in one warning (logger `ramp.accel`); a stale one in one info line (the normal state of a tree
being edited: make rebuilds it); no build at all, or `RAMP_ACCEL=0`, is silent. `status()`
says why either way (the mission summary and the bench report it).
The compiled code computes what the sources compute (mission summaries were compared bit for
bit); only the speed differs.

A leaf of `ramp.common`: it imports nothing of RAMP, and never imports the modules it serves.
"""

from __future__ import annotations

import hashlib
import importlib.abc
import importlib.machinery
import importlib.util
import json
import logging
import os
import sys
import sysconfig
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

#: The repository root of an editable install (ramp/common/accel.py -> the root).
ROOT = Path(__file__).resolve().parents[2]
#: Where scripts/build_accel.py writes the extension modules and the manifest.
BUILD_DIR = ROOT / "build" / "accel"
MANIFEST = "manifest.json"
log = logging.getLogger("ramp.accel")


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
        platform = manifest.get("platform", sysconfig.get_platform())
        if platform != sysconfig.get_platform():
            return {}, f"built for {platform}, this is {sysconfig.get_platform()}"
        files: dict[str, Path] = {}
        hashed = [(e["source"], e["sha256"]) for e in manifest.get("modules", {}).values()]
        hashed += list(manifest.get("inputs", {}).items())
        for source, sha256 in hashed:
            try:
                same = _sha256(root / source) == sha256
            except OSError:
                same = False
            if not same:
                return {}, f"{source} changed since the build (run make accel)"
        extensions = {name: e["extension"] for name, e in manifest.get("modules", {}).items()}
        extensions.update(manifest.get("runtime", {}))
        for name, ext in extensions.items():
            if not str(ext).endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)):
                return {}, (f"{ext} is not an extension module of this interpreter (built "
                            f"for another platform or ABI)")
            files[name] = build_dir / ext
    except (AttributeError, KeyError, TypeError, ValueError) as exc:  # JSON, not a manifest
        return {}, f"unreadable manifest {build_dir / MANIFEST}: no {exc} where expected"
    missing = [str(path) for path in files.values() if not path.is_file()]
    if missing:
        return {}, f"the build is incomplete: {missing[0]} is missing (run make accel)"
    return files, ""


class CompiledFinder(importlib.abc.MetaPathFinder):
    """Finds the compiled build of the modules it was given, and nothing else; the first one
    that fails to import turns it off (`give_up`), and that module loads from its source."""

    def __init__(self, files: dict[str, Path]) -> None:
        self.files = files

    def find_spec(self, fullname: str, path: object = None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        file = self.files.get(fullname)
        if file is None:
            return None
        loader = _CompiledOrSource(self, fullname, file, path)
        return importlib.util.spec_from_file_location(fullname, file, loader=loader)

    def give_up(self, why: str) -> None:
        """Serve nothing more; the modules already imported compiled stay as they are."""
        global _status
        if self.files:
            self.files = {}
            _status = AccelStatus(False, why)
            log.warning("the compiled hot path cannot be used, running the sources: %s", why)


class _CompiledOrSource(importlib.abc.Loader):
    """The extension module, or its source when the extension fails to import."""

    def __init__(self, finder: CompiledFinder, name: str, file: Path, path: object) -> None:
        self.finder = finder
        self.compiled = importlib.machinery.ExtensionFileLoader(name, str(file))
        self.path = path
        self.source: importlib.machinery.ModuleSpec | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        try:
            return self.compiled.create_module(spec)
        except ImportError as exc:  # another platform's binary, a missing symbol
            self.finder.give_up(f"{self.compiled.path} failed to import: {exc}")
            search = self.path if isinstance(self.path, list) else None
            self.source = importlib.machinery.PathFinder.find_spec(spec.name, search)
            if self.source is None or self.source.loader is None:
                raise
            spec.origin = self.source.origin
            spec.cached = self.source.cached
            return self.source.loader.create_module(self.source)

    def exec_module(self, module: ModuleType) -> None:
        if self.source is not None and self.source.loader is not None:
            module.__file__ = self.source.origin
            self.source.loader.exec_module(module)
        else:
            self.compiled.exec_module(module)


def _load_runtime(files: dict[str, Path]) -> str:
    """Import the build's shared runtime (it imports nothing of RAMP): '' or why it failed.
    A binary for another platform or ABI fails here, before any module is served."""
    for name, file in files.items():
        if "." in name or name in sys.modules:
            continue
        try:
            loader = importlib.machinery.ExtensionFileLoader(name, str(file))
            spec = importlib.util.spec_from_file_location(name, file, loader=loader)
            assert spec is not None
            module = importlib.util.module_from_spec(spec)
            loader.exec_module(module)
            sys.modules[name] = module
        except (ImportError, OSError) as exc:
            return f"{file} failed to import: {exc}"
    return ""


def install(build_dir: Path = BUILD_DIR, root: Path = ROOT) -> AccelStatus:
    """Serve the compiled modules from now on when the build is current (idempotent)."""
    global _status
    if any(isinstance(finder, CompiledFinder) for finder in sys.meta_path):
        return _status
    if os.environ.get("RAMP_ACCEL", "1") == "0":
        _status = AccelStatus(False, "turned off (RAMP_ACCEL=0)")
        return _status
    files, why = check(build_dir, root)
    if files:
        why = _load_runtime(files)
    if why:
        _status = AccelStatus(False, why)
        if (build_dir / MANIFEST).exists():  # a build that is there and cannot be used
            # Stale is the normal state of a tree being edited (make rebuilds it before the
            # tests); one that is broken or foreign is a warning.
            level = logging.INFO if "changed since the build" in why else logging.WARNING
            log.log(level, "the compiled hot path cannot be used, running the sources: %s", why)
        return _status
    sys.meta_path.insert(0, CompiledFinder(files))
    modules = sorted(name for name in files if "." in name)
    _status = AccelStatus(True, "", modules)
    return _status
