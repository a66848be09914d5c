"""The flight recorder never loses data silently (issue 19 item 9): a `dir` no file system
takes is refused at load, a writer that cannot write counts every record and keeps retrying,
a file deleted or replaced mid-run is noticed, and rotation and pruning cost the same in a
directory of thousands of files as in an empty one."""

from __future__ import annotations

import logging
import os
import re
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import pytest

from ramp.cli import main as ramp_main
from ramp.recorder import Recorder, RecorderConfig
from ramp.recorder import writer as writer_module
from ramp.recorder.reading import Recording
from ramp.recorder.writer import default_opener, recording_files

ORIGIN = 1_779_285_600_000_000_000


def wait_for(cond: Callable[[], bool], seconds: float = 10.0) -> bool:
    deadline = time.monotonic() + seconds
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.01)
    return cond()


def test_a_nul_byte_in_the_recorder_dir_is_refused_at_load(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "ramp.yaml"
    f.write_text('buses:\n  io: {driver: sim}\nmodules:\n  demo: {motor: {bus: io}, '
                 'lamp: {bus: io}}\nrecorder:\n  dir: "rec\\0x"\n')
    assert ramp_main(["check", str(f)]) == 2  # before: 0, and the writer died at run time
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"{f}:6: recorder.dir: ") and "NUL byte" in err[0], err


def test_a_writer_that_cannot_open_counts_every_record_warns_once_and_retries(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """An opener that raises what `open` raises for a NUL in a path (ValueError): before,
    the writer thread died with a traceback and `dropped` stayed 0."""
    broken = [True]

    def opener(path: Path) -> IO[bytes]:
        if broken[0]:
            raise ValueError("embedded null byte")
        return default_opener(path)

    caplog.set_level(logging.INFO, logger="ramp.recorder")
    rec = Recorder(RecorderConfig(str(tmp_path / "rec")), origin_ns=ORIGIN, opener=opener,
                   flush_s=0.02, retry_s=0.2)
    rec.start(0.0, wait_for_file=False)
    for i in range(100):
        rec.event(i * 0.01, "note", f"n{i}")
    assert wait_for(lambda: rec.dropped == 100 and rec.queued == 0)
    thread = rec._thread
    assert thread is not None and thread.is_alive()
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and "embedded null byte" in warnings[0].getMessage()
    broken[0] = False
    time.sleep(0.25)  # past retry_s
    rec.event(2.0, "note", "after")
    rec.close()
    assert rec.dropped == 100 and rec.written == 1
    assert len([r for r in caplog.records if r.levelno >= logging.WARNING]) == 1


def events_in(path: Path) -> list[str]:
    rec = Recording([path], progress=False)
    return [m.data["text"] for m in rec if m.topic == "/robot/events"]


@pytest.mark.parametrize("how", ["deleted", "replaced by a directory", "replaced by a file"])
def test_the_current_file_deleted_or_replaced_mid_run_starts_a_new_file_with_a_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture, how: str) -> None:
    caplog.set_level(logging.WARNING, logger="ramp.recorder")
    rec = Recorder(RecorderConfig(str(tmp_path / "rec")), origin_ns=ORIGIN, flush_s=0.02)
    rec.start(0.0)
    first = rec.path
    assert first is not None
    rec.event(0.0, "note", "before")
    assert wait_for(lambda: rec.written == 1 and rec.queued == 0)
    time.sleep(0.05)  # one timed check finds the file still ours
    first.unlink()
    if how == "replaced by a directory":
        first.mkdir()
    elif how == "replaced by a file":
        first.write_bytes(b"someone else's")
    assert wait_for(lambda: any("while being written" in r.getMessage()
                                for r in caplog.records))
    rec.event(1.0, "note", "after")
    rec.close()
    second = rec.path
    assert second is not None and second != first  # before: kept writing the lost file
    assert events_in(second) == ["after"]
    warning = next(r.getMessage() for r in caplog.records if "while being written" in
                   r.getMessage())
    assert str(first) in warning and ("deleted" if how == "deleted" else "replaced") in warning
    assert rec.dropped == 0  # "before" was checked safe before the file went


def test_a_record_written_into_a_file_already_deleted_is_counted_lost(
        tmp_path: Path) -> None:
    rec = Recorder(RecorderConfig(str(tmp_path / "rec")), origin_ns=ORIGIN, flush_s=0.3)
    rec.start(0.0)
    assert rec.path is not None
    rec.path.unlink()
    rec.event(0.0, "note", "into the void")
    assert wait_for(lambda: rec.dropped == 1, 5.0)  # before: dropped=0 until rotation
    rec.close()


@pytest.mark.timeout(60)
def test_rotation_never_rescans_a_crowded_directory_and_pruning_logs_one_line(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """3,000 files of an earlier run and keep 1. Before: every rotation listed the whole
    directory (twice) and every removal logged a line."""
    d = tmp_path / "rec"
    d.mkdir()
    for i in range(1, 3001):
        (d / f"ramp-{i:06d}-20260101T000000Z.mcap").write_bytes(b"")
    (d / "notes.txt").write_text("not ours")
    scans: list[Any] = []
    real_scandir = os.scandir

    def counting_scandir(path: Any) -> Any:
        scans.append(path)
        return real_scandir(path)

    monkeypatch.setattr(writer_module.os, "scandir", counting_scandir)
    monkeypatch.setattr(Path, "iterdir", lambda self: pytest.fail("a directory listing"))
    caplog.set_level(logging.INFO, logger="ramp.recorder")
    rec = Recorder(RecorderConfig(str(d), max_mb=0.02, keep=1), origin_ns=ORIGIN,
                   compression="none", flush_s=0.02)
    rec.start(0.0)
    for i in range(1500):  # several rotations
        rec.command(i * 0.01, "base_motors", "base.lf_wheel", 0.5)
    rec.close()
    monkeypatch.undo()
    files = recording_files(d)
    assert len(scans) == 1
    assert len(files) == 1 and files[0][0] > 3002 and (d / "notes.txt").exists()
    removed = [r.getMessage() for r in caplog.records if "removed" in r.getMessage()]
    assert 1 <= len(removed) <= 4, removed[:5]  # before: one line per file, 3,000 and more
    assert re.search(r"removed 30\d\d files \(ramp-000001-\S+ to ramp-", removed[0])
    assert rec.dropped == 0
    shutil.rmtree(d)
