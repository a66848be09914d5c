"""A recording process killed with SIGKILL leaves a file the `mcap` reader reads, missing
at most the last second."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader

from ramp.recorder.reading import Recording
from ramp.recorder.writer import TimeBase

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(60)
def test_a_sigkilled_recording_is_readable_and_misses_at_most_the_last_second(
        tmp_path: Path) -> None:
    proc = subprocess.Popen([sys.executable, "-m", "tests.unit.recorder_child", str(tmp_path)],
                            cwd=REPO, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("recording "), line
        path = Path(line.split(" ", 1)[1].strip())
        time.sleep(2.5)
        killed_at = time.monotonic()  # CLOCK_MONOTONIC: the child's clock too
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL

    # The mcap library's own stream reader reads it, up to where the file ends.
    seqs = []
    with open(path, "rb") as f, contextlib.suppress(McapError):
        for _, channel, message in NonSeekingReader(f, validate_crcs=True).iter_messages(
                log_time_order=False):
            if channel.topic == "/robot/commands":
                seqs.append(message.sequence)
    assert seqs == list(range(1, len(seqs) + 1))  # in order, none missing before the cut

    recording = Recording([path])
    times = [m.log_time for m in recording]
    info = recording.files[0]
    assert not info.complete  # no footer: the process never closed it
    meta = info.metadata["ramp"]
    tb = TimeBase(float(meta["clock_t0_s"]), int(meta["clock_origin_ns"]))
    last = tb.seconds(max(times))
    print(f"lost {killed_at - last:.3f} s before the kill")
    assert killed_at - last <= 1.0, f"lost {killed_at - last:.3f} s before the kill"
    assert len(times) >= 150  # about 2 s of 110 records a second were kept
