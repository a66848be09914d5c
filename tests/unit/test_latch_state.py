"""Where the latch state lives, and a state directory that cannot be written (SPEC 2.2)."""

from __future__ import annotations

import logging
from pathlib import Path
from types import SimpleNamespace

import pytest

from ramp.common.state_files import default_state_dir
from ramp.layers.functional.latch import FaultLatch
from ramp.runtime.latch_state import LatchState, state_file


def test_the_state_directory_follows_systemd_then_xdg(monkeypatch: pytest.MonkeyPatch,
                                                      tmp_path: Path) -> None:
    monkeypatch.setenv("STATE_DIRECTORY", "/var/lib/ramp:/var/lib/other")
    assert default_state_dir() == Path("/var/lib/ramp")
    monkeypatch.delenv("STATE_DIRECTORY")
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    assert default_state_dir() == tmp_path / "ramp"
    monkeypatch.delenv("XDG_STATE_HOME")
    assert default_state_dir() == Path.home() / ".local" / "state" / "ramp"


def test_one_file_per_config(tmp_path: Path) -> None:
    a, b = state_file(tmp_path, "ramp.yaml"), state_file(tmp_path, "robots/ramp.yaml")
    assert a != b and a.name.startswith("latches-ramp-") and a.parent == tmp_path
    assert state_file(tmp_path, "ramp.yaml") == a


def test_an_unwritable_directory_costs_persistence_only(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("")
    latch = FaultLatch("lift")
    module = SimpleNamespace(latches={"lift": latch})
    interlocks = SimpleNamespace(rules=[], latch_changes=0, latched_names=lambda: (),
                                 restore_latched=lambda names: list(names))
    state = LatchState(blocker / "latches.json")
    with caplog.at_level(logging.WARNING, logger="ramp.latches"):
        state.restore({"ble": SimpleNamespace(module=module)}, interlocks)
        latch.trip("stalled")
        state.check(0.1, 0.1)
        latch.clear()
        latch.trip("stalled again")
        state.check(0.2, 0.1)
    warnings = [r.getMessage() for r in caplog.records if "cannot keep" in r.getMessage()]
    assert len(warnings) == 1, warnings
    assert latch.latched  # the latch itself holds
