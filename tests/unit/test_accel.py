"""The compiled hot path (ramp/common/accel.py): used only when it matches the sources, and
computing what they compute."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType

import pytest

from ramp.clock import VirtualClock
from ramp.common import accel


def _build(tmp_path: Path, source_text: str = "x = 1\n", **overrides: object) -> Path:
    root = tmp_path / "root"
    (root / "pkg").mkdir(parents=True)
    (root / "pkg" / "hot.py").write_text(source_text)
    build = tmp_path / "build"
    (build / "pkg").mkdir(parents=True)
    (build / "pkg" / "hot.so").write_bytes(b"")
    (build / "group__mypyc.so").write_bytes(b"")
    manifest = {
        "cache_tag": sys.implementation.cache_tag,
        "modules": {"pkg.hot": {"source": "pkg/hot.py", "extension": "pkg/hot.so",
                                "sha256": hashlib.sha256(source_text.encode()).hexdigest()}},
        "runtime": {"group__mypyc": "group__mypyc.so"},
    }
    manifest.update(overrides)
    (build / accel.MANIFEST).write_text(json.dumps(manifest))
    return root


def test_a_build_that_matches_its_sources_is_served(tmp_path: Path) -> None:
    root = _build(tmp_path)
    files, why = accel.check(tmp_path / "build", root)
    assert why == ""
    assert set(files) == {"pkg.hot", "group__mypyc"}
    spec = accel.CompiledFinder(files).find_spec("pkg.hot")
    assert spec is not None and spec.origin == str(tmp_path / "build" / "pkg" / "hot.so")
    assert accel.CompiledFinder(files).find_spec("pkg.cold") is None


def test_an_edited_source_turns_the_whole_build_off(tmp_path: Path) -> None:
    root = _build(tmp_path)
    (root / "pkg" / "hot.py").write_text("x = 2\n")
    files, why = accel.check(tmp_path / "build", root)
    assert files == {} and "pkg/hot.py changed since the build" in why


def test_no_build_a_build_for_another_python_and_a_partial_build_are_not_used(
        tmp_path: Path) -> None:
    assert "not built" in accel.check(tmp_path / "nothing", tmp_path)[1]
    root = _build(tmp_path, cache_tag="cpython-299")
    assert "built for cpython-299" in accel.check(tmp_path / "build", root)[1]
    root = _build(tmp_path / "again")
    (tmp_path / "again" / "build" / "pkg" / "hot.so").unlink()
    assert "incomplete" in accel.check(tmp_path / "again" / "build", root)[1]


def test_a_manifest_that_is_not_one_is_reported_not_raised(tmp_path: Path) -> None:
    no_source = {"cache_tag": sys.implementation.cache_tag, "modules": {"pkg.hot": {}}}
    for manifest in ([], no_source):
        (tmp_path / accel.MANIFEST).write_text(json.dumps(manifest))
        files, why = accel.check(tmp_path, tmp_path)
        assert files == {} and why.startswith("unreadable manifest")


def test_ramp_accel_0_turns_it_off(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("RAMP_ACCEL", "0")
    monkeypatch.setattr(sys, "meta_path", [f for f in sys.meta_path
                                           if not isinstance(f, accel.CompiledFinder)])
    assert accel.install().reason == "turned off (RAMP_ACCEL=0)"
    assert not any(isinstance(f, accel.CompiledFinder) for f in sys.meta_path)


def _source_copy(name: str) -> ModuleType:
    """The module `name` run from its source under another name, beside its compiled self."""
    path = accel.ROOT / (name.replace(".", "/") + ".py")
    spec = importlib.util.spec_from_file_location(f"_source_of_{name.replace('.', '_')}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    try:
        spec.loader.exec_module(module)
    finally:
        del sys.modules[spec.name]
    return module


needs_build = pytest.mark.skipif(
    not accel.status().active, reason=f"the compiled hot path is not in use: "
                                      f"{accel.status().reason}")


@needs_build
def test_the_compiled_world_and_imu_give_the_sources_results_bit_for_bit() -> None:
    import firmware_like.imu as imu_compiled
    import firmware_like.marte as marte_compiled

    assert imu_compiled.__file__ is not None and imu_compiled.__file__.endswith(".so")
    runs = []
    for marte, imu in ((marte_compiled, imu_compiled),
                       (_source_copy("firmware_like.marte"), _source_copy("firmware_like.imu"))):
        world = marte.MarteWorld(seed=3)
        clock = VirtualClock()
        emulator = imu.ImuEmulator(clock, world.imu_truth, seed=3, fault="gyro-drift")
        samples = []
        for i in range(600):  # 6 s: away, a turn on the spot, back
            duty = 0.6 if i < 200 else (0.0 if i < 400 else -0.5)
            turn = 0.4 if 200 <= i < 400 else 0.0
            for wheel in marte.LEFT_WHEELS:
                world.set_motor(wheel, duty - turn)
            for wheel in marte.RIGHT_WHEELS:
                world.set_motor(wheel, duty + turn)
            world.step(0.01)
            clock.advance(0.01)
            samples.extend(emulator.poll())
        runs.append((world.truth(), [tuple(s) for s in samples]))
    assert runs[0] == runs[1]
    assert len(runs[0][1]) == 750
