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


def _build_script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("_build_accel",
                                                  accel.ROOT / "scripts" / "build_accel.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_build_hashes_every_first_party_module_a_compiled_one_imports(
        tmp_path: Path) -> None:
    """mypyc copies a `Final` of a module it does not compile: those sources count too."""
    script = _build_script()
    root = tmp_path
    (root / "ramp" / "hal").mkdir(parents=True)
    (root / "ramp" / "__init__.py").write_text("")
    (root / "ramp" / "hal" / "__init__.py").write_text("")
    (root / "ramp" / "hot.py").write_text(
        "import json\nfrom ramp.hal.codec import BAUD\nfrom typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from ramp import typed_only\n")
    (root / "ramp" / "hal" / "codec.py").write_text("from .limits import MAX\nBAUD = 9600\n")
    (root / "ramp" / "hal" / "limits.py").write_text("MAX = 127\n")
    (root / "ramp" / "typed_only.py").write_text("")
    (root / "ramp" / "unrelated.py").write_text("")
    assert script.inputs(["ramp/hot.py"], root) == [
        "ramp/__init__.py", "ramp/hal/__init__.py", "ramp/hal/codec.py", "ramp/hal/limits.py",
        "ramp/hot.py", "ramp/typed_only.py"]


def test_an_edited_module_that_is_only_imported_makes_the_build_stale(tmp_path: Path) -> None:
    root = _build(tmp_path, inputs={"pkg/consts.py": hashlib.sha256(b"BAUD = 9600\n")
                                    .hexdigest()})
    (root / "pkg" / "consts.py").write_text("BAUD = 9600\n")
    assert accel.check(tmp_path / "build", root)[1] == ""
    (root / "pkg" / "consts.py").write_text("BAUD = 19200\n")
    files, why = accel.check(tmp_path / "build", root)
    assert files == {} and "pkg/consts.py changed since the build" in why


def test_a_build_for_another_platform_or_abi_is_not_used(tmp_path: Path) -> None:
    root = _build(tmp_path, platform="win-amd64")
    assert "built for win-amd64" in accel.check(tmp_path / "build", root)[1]
    root = _build(tmp_path / "arm", runtime={"group__mypyc": "group__mypyc.cpython-311-"
                                                             "aarch64-linux-gnu.dylib"})
    why = accel.check(tmp_path / "arm" / "build", root)[1]
    assert "not an extension module of this interpreter" in why


@pytest.fixture
def no_finder(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("RAMP_ACCEL", raising=False)
    monkeypatch.setattr(sys, "meta_path", [f for f in sys.meta_path
                                           if not isinstance(f, accel.CompiledFinder)])
    monkeypatch.setattr(accel, "_status", accel.status())


def test_a_build_that_fails_to_import_falls_back_with_one_warning(
        tmp_path: Path, no_finder: None, caplog: pytest.LogCaptureFixture) -> None:
    """A binary of another machine (here: not an ELF at all) for this interpreter's suffix:
    RAMP runs the sources and says why, once."""
    root = _build(tmp_path)
    (tmp_path / "build" / "group__mypyc.so").write_bytes(b"not a shared object")
    with caplog.at_level("WARNING", logger="ramp.accel"):
        status = accel.install(tmp_path / "build", root)
    assert not status.active and "group__mypyc.so failed to import" in status.reason
    assert not any(isinstance(f, accel.CompiledFinder) for f in sys.meta_path)
    assert [r.getMessage() for r in caplog.records].count(
        f"the compiled hot path cannot be used, running the sources: {status.reason}") == 1


def test_a_module_that_fails_to_import_loads_its_source_and_turns_the_build_off(
        tmp_path: Path, no_finder: None, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    root = tmp_path / "root"
    (root / "accelpkg").mkdir(parents=True)
    (root / "accelpkg" / "__init__.py").write_text("")
    (root / "accelpkg" / "hot.py").write_text("X = 7\n")
    (root / "accelpkg" / "cold.py").write_text("Y = 8\n")
    bad = tmp_path / "hot.so"
    bad.write_bytes(b"\x7fELF garbage")
    monkeypatch.syspath_prepend(str(root))
    finder = accel.CompiledFinder({"accelpkg.hot": bad, "accelpkg.cold": bad})
    monkeypatch.setattr(sys, "meta_path", [finder, *sys.meta_path])
    with caplog.at_level("WARNING", logger="ramp.accel"):
        import accelpkg.cold  # type: ignore[import-not-found]
        import accelpkg.hot  # type: ignore[import-not-found]
    try:
        assert accelpkg.hot.X == 7 and accelpkg.cold.Y == 8
        assert accelpkg.cold.__file__ == str(root / "accelpkg" / "cold.py")
        assert finder.files == {} and not accel.status().active
        assert len(caplog.records) == 1 and "hot.so failed to import" in caplog.text
    finally:
        for name in ("accelpkg", "accelpkg.hot", "accelpkg.cold"):
            sys.modules.pop(name, None)


#: Where a compiled module may live: the simulator's physics and emulators, the autonomy's
#: per-sample maths. The robot's safety path runs its sources in the tests as on the robot.
COMPILABLE = ("firmware_like/", "ramp/simulation/backplane.py", "ramp/autonomy/perception/",
              "ramp/autonomy/planning/follower.py", "ramp/autonomy/planning/geometry.py",
              "ramp/autonomy/odometry.py", "ramp/autonomy/mount.py")


def test_nothing_on_the_robots_safety_path_is_compiled() -> None:
    modules = _build_script().MODULES
    assert modules and all(m.startswith(COMPILABLE) for m in modules), modules
    for path in ("ramp/scheduler.py", "ramp/hal/sabertooth.py", "ramp/runtime/buses.py",
                 "ramp/layers/robot_distribution/interlocks.py", "ramp/layers/server/tcp.py",
                 "ramp/layers/functional/base_drive.py"):
        assert path not in modules


def test_the_backend_runs_its_sources_whether_or_not_the_build_is_used() -> None:
    import ramp.hal.sabertooth
    import ramp.layers.robot_distribution.interlocks
    import ramp.layers.server.tcp
    import ramp.runtime.buses
    import ramp.scheduler

    for module in (ramp.scheduler, ramp.layers.server.tcp, ramp.hal.sabertooth,
                   ramp.runtime.buses, ramp.layers.robot_distribution.interlocks):
        assert module.__file__ is not None and module.__file__.endswith(".py"), module


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


def test_a_stale_build_is_one_info_line_not_a_warning(
        tmp_path: Path, no_finder: None, caplog: pytest.LogCaptureFixture) -> None:
    root = _build(tmp_path)
    (root / "pkg" / "hot.py").write_text("x = 2\n")
    with caplog.at_level("INFO", logger="ramp.accel"):
        status = accel.install(tmp_path / "build", root)
    assert not status.active and "pkg/hot.py changed since the build" in status.reason
    assert [r.levelname for r in caplog.records] == ["INFO"]
