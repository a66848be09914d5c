"""scripts/pick_python.py: the Makefile's choice of interpreter for .venv."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "pick_python.py"


def _load():  # the script is not a package module
    spec = importlib.util.spec_from_file_location("pick_python", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_prints_the_interpreter_exactly_when_it_is_usable() -> None:
    pick = _load()
    out = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True)
    if pick.usable():
        assert out.returncode == 0 and out.stdout == sys.executable + "\n"
    else:
        assert out.returncode == 1 and out.stdout == ""


def test_refuses_a_python_without_headers(monkeypatch: pytest.MonkeyPatch,
                                          tmp_path: Path) -> None:
    pick = _load()
    if not pick.usable():
        pytest.skip("this Python fails an earlier check (venv, ensurepip)")
    paths = dict(sysconfig.get_paths(), include=str(tmp_path))  # no Python.h there
    monkeypatch.setattr(pick.sysconfig, "get_paths", lambda: paths)
    assert pick.usable() is False


def test_refuses_a_python_older_than_3_11(monkeypatch: pytest.MonkeyPatch) -> None:
    pick = _load()
    monkeypatch.setattr(pick.sys, "version_info", (3, 10, 12))
    assert pick.usable() is False


def test_refuses_a_python_that_cannot_make_a_venv(monkeypatch: pytest.MonkeyPatch) -> None:
    pick = _load()
    real = pick.importlib.util.find_spec
    monkeypatch.setattr(pick.importlib.util, "find_spec",
                        lambda name: None if name == "ensurepip" else real(name))
    assert pick.usable() is False
