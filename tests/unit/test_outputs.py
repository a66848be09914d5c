"""Files a command writes: a path that cannot be written is a usage error before any work,
and a picture lands exactly where the command says it does."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import pytest

from ramp import cli
from ramp.common import outputs
from ramp.common.outputs import OutputError, check_output, figure_file, save_figure
from ramp.recorder.logcli import main as log_main


def test_missing_directories_are_made_and_no_empty_file_is_left(tmp_path: Path) -> None:
    target = tmp_path / "a" / "b" / "plot.png"
    assert check_output(target) == target
    assert target.parent.is_dir()
    assert not target.exists()


def test_an_existing_file_is_kept_as_it_is(tmp_path: Path) -> None:
    target = tmp_path / "trace.jsonl"
    target.write_text("earlier run\n")
    check_output(target)
    assert target.read_text() == "earlier run\n"


@pytest.mark.parametrize("make, why", [
    (lambda p: p.mkdir(), "it is a directory"),
    (lambda p: os.mkfifo(p), "it is a FIFO"),
])
def test_a_directory_or_a_fifo_is_refused_without_waiting(tmp_path: Path, make, why) -> None:
    target = tmp_path / "out"
    make(target)
    with pytest.raises(OutputError, match=why):
        check_output(target)


def test_a_path_below_a_file_is_refused_in_words(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("x")
    bad = tmp_path / "notes.txt" / "plot.png"
    with pytest.raises(OutputError) as info:
        check_output(bad)
    assert str(info.value).startswith(f"cannot write {bad}: ")
    assert "Not a directory" in str(info.value)


def test_an_empty_name_is_refused() -> None:
    with pytest.raises(OutputError, match="expected a file name"):
        check_output("  ")


@pytest.mark.parametrize("name, magic", [("scan", b"\x89PNG"), ("scan.png", b"\x89PNG"),
                                         ("scan.svg", b"<?xml"), ("scan.unknown", b"\x89PNG")])
def test_a_figure_is_written_exactly_where_asked(tmp_path: Path, name: str,
                                                 magic: bytes) -> None:
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    out = tmp_path / "new" / name
    assert save_figure(fig, out) == out
    plt.close(fig)
    assert out.read_bytes().startswith(magic)
    assert [p.name for p in out.parent.iterdir()] == [name]  # not `scan.png` beside `scan`


def _bad_path(tmp_path: Path) -> Path:
    (tmp_path / "file").write_text("x")
    return tmp_path / "file" / "out.png"


@pytest.mark.parametrize("argv", [
    ["sim", "mission", "--plot"],
    ["sim", "mission", "--trace"],
    ["sim", "mission", "--record"],
    ["sim", "lidar", "--at", "1,2,0", "--plot"],
    ["sim", "perceive", "--at", "0.8,2.9,0", "--plot"],
])
def test_sim_commands_refuse_an_unwritable_output_before_running(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    bad = _bad_path(tmp_path)
    with pytest.raises(SystemExit) as info:
        cli.main([*argv, str(bad)])
    assert info.value.code == 2
    err = capsys.readouterr()
    assert f"cannot write {bad}: Not a directory" in err.err
    assert "Traceback" not in err.err
    assert err.out == ""  # no state change printed: the mission never started


def test_log_plot_refuses_an_unwritable_picture_before_reading(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = _bad_path(tmp_path)
    with pytest.raises(SystemExit) as info:
        log_main(["plot", str(tmp_path / "missing.mcap"), "-o", str(bad)])
    assert info.value.code == 2
    assert f"cannot write {bad}" in capsys.readouterr().err


def test_a_picture_named_without_a_suffix_is_written_as_png_and_named_so(
        tmp_path: Path) -> None:
    (tmp_path / "plots").mkdir()
    assert figure_file(str(tmp_path / "scan")) == str(tmp_path / "scan.png")
    assert figure_file(str(tmp_path / "plots")) == str(tmp_path / "plots.png")  # not the dir
    assert figure_file(str(tmp_path / "scan.svg")) == str(tmp_path / "scan.svg")
    with pytest.raises(argparse.ArgumentTypeError, match="expected a file name"):
        figure_file("")


@pytest.mark.parametrize("argv", [
    ["sim", "mission", "--seed", "1"],
    ["sim", "lidar", "--at", "1,2,0"],
    ["sim", "perceive", "--at", "0.8,2.9,0"],
])
def test_sim_commands_refuse_a_plot_without_matplotlib_before_running(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        argv: list[str]) -> None:
    real = outputs.importlib.util.find_spec
    monkeypatch.setattr(outputs.importlib.util, "find_spec",
                        lambda name, *a: None if name == "matplotlib" else real(name, *a))
    import ramp.simulation.perceive as perceive_module

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("the work started")

    monkeypatch.setattr(perceive_module, "perceive", never)
    rc = cli.main([*argv, "--plot", str(tmp_path / "out.png")])
    err = capsys.readouterr()
    assert rc == 2, err
    assert "--plot needs matplotlib: pip install 'ramp[plot]'" in err.err
    assert not (tmp_path / "out.png").exists()
