"""The flight recorder wired into the supervisor (`ramp.runtime.recording`): the `recorder:`
block and `--record`, `robot:recorder.dropped=(n)`, a disk that blocks or cannot be written
(the supervisor keeps running, drops are counted, one warning), the observer fan-out, and
recording off costing nothing. On a virtual clock; the whole-process tests are in
tests/hil_sim/test_recorder_run.py."""

from __future__ import annotations

import io
import logging
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from ramp.cli import main as ramp_main
from ramp.config import parse_config
from ramp.recorder import Recorder, RecorderConfig
from ramp.runtime import Observer, Supervisor
from ramp.runtime.observers import FanOut, fan_out, overridden
from ramp.runtime.recording import recorder_config
from tests.harness import DEMO_YAML, REPO, Harness

MARTE = (REPO / "ramp.yaml").read_text()


def parse(block: str, name: str = "robot.yaml") -> tuple[Any, list[str]]:
    text = MARTE + "\n" + block + "\n"
    cfg, errors = parse_config(text, name)
    return cfg, [str(e) for e in errors]


def test_without_the_block_nothing_is_recorded_and_a_null_block_is_off() -> None:
    assert parse("")[0].recorder is None
    assert parse("recorder:")[0].recorder is None


def test_the_block_is_read_and_a_relative_dir_is_relative_to_the_config_file() -> None:
    cfg, errors = parse("recorder: {dir: /var/lib/ramp/rec, max_mb: 50, keep: 4}")
    assert errors == []
    assert cfg.recorder == RecorderConfig("/var/lib/ramp/rec", 50.0, 4)
    cfg, _ = parse("recorder: {dir: rec}", "/etc/ramp/ramp.yaml")
    assert cfg.recorder == RecorderConfig("/etc/ramp/rec")  # defaults: 100 MB, 20 files


def test_a_bad_block_names_the_file_line_and_key() -> None:
    line = MARTE.count("\n") + 2
    cases = {
        "recorder: {}": f"robot.yaml:{line}: recorder.dir: missing; expected a directory",
        "recorder: {dir: rec, max_mb: 0}": f"robot.yaml:{line}: recorder.max_mb: 0 is not a "
                                           "file size in MB",
        "recorder: {dir: rec, keep: -1}": f"robot.yaml:{line}: recorder.keep: -1 is not how "
                                          "many files to keep",
        "recorder: {dir: rec, size: 5}": f"robot.yaml:{line}: recorder.size: unknown key "
                                         "(expected one of: dir, keep, max_mb)",
        "recorder: {dir: ''}": f"robot.yaml:{line}: recorder.dir: '' is not a directory",
        "recorder: /var/lib/ramp": f"robot.yaml:{line}: recorder: expected a mapping, got a "
                                   "string",
        "recorder:\n  dir: rec\n  max_mb: lots": f"robot.yaml:{line + 2}: recorder.max_mb: "
                                                 "'lots' is not a file size",
    }
    for block, expected in cases.items():
        cfg, errors = parse(block)
        assert cfg is None and len(errors) == 1, (block, errors)
        assert errors[0].startswith(expected), (block, errors[0])


def test_ramp_check_reports_a_bad_block_with_status_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "ramp.yaml"
    path.write_text(MARTE + "\nrecorder: {dir: rec, keep: 0}\n")
    assert ramp_main(["check", str(path)]) == 2
    assert f"{path}:{MARTE.count(chr(10)) + 2}: recorder.keep: 0 is not" in capsys.readouterr().err


def test_record_overrides_the_dir_and_keeps_the_blocks_sizes() -> None:
    with_block, _ = parse("recorder: {dir: /var/lib/ramp/rec, max_mb: 5, keep: 3}")
    without, _ = parse("")
    assert recorder_config(with_block, None) == RecorderConfig("/var/lib/ramp/rec", 5, 3)
    assert recorder_config(with_block, "/tmp/x") == RecorderConfig("/tmp/x", 5, 3)
    assert recorder_config(without, "/tmp/x") == RecorderConfig("/tmp/x")
    assert recorder_config(without, None) is None


def test_an_empty_record_dir_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        ramp_main(["run", "--record", " ", "--sim"])
    assert exc.value.code == 2
    assert "--record: expected a directory" in capsys.readouterr().err


@pytest.mark.parametrize("where", ["/dev/null", "{tmp}/file", "{tmp}/file/below"])
def test_a_record_dir_that_cannot_be_a_directory_is_a_usage_error(
        where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--record /dev/null` ran the supervisor recording nothing, with a warning every 5 s."""
    (tmp_path / "file").write_text("")
    path = where.format(tmp=tmp_path)
    with pytest.raises(SystemExit) as exc:
        ramp_main(["run", "--record", path, "--sim"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"--record: cannot record into {path}: " in err and "Traceback" not in err


def test_a_missing_record_dir_is_made_as_the_command_line_is_read(tmp_path: Path) -> None:
    from ramp.cli import build_parser

    args = build_parser().parse_args(["run", "--record", str(tmp_path / "a" / "b"), "--sim"])
    assert args.record == str(tmp_path / "a" / "b") and (tmp_path / "a" / "b").is_dir()


# -- the running supervisor -------------------------------------------------------------------
class GatedFile(io.BytesIO):
    """A disk that blocks every write while its gate is shut."""

    def __init__(self) -> None:
        super().__init__()
        self.gate = threading.Event()
        self.gate.set()
        self.blocked = threading.Event()

    def write(self, data: Any) -> int:
        if not self.gate.is_set():
            self.blocked.set()
            self.gate.wait(30)
        return super().write(data)


def test_robot_get_counts_drops_behind_a_blocked_disk_and_the_tick_never_waits(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    disk = GatedFile()
    rec = Recorder(RecorderConfig(str(tmp_path / "rec")), opener=lambda path: disk,
                   queue_records=200, flush_s=0.01)
    h = Harness(recorder=rec)
    try:
        c = h.connect()
        assert "robot:recorder.property=(dropped,int)" in c.ask("robot:robot.describe=()")
        assert "robot:recorder.dropped=(0)" in c.ask("robot:robot.get=()")
        deadline = time.monotonic() + 10
        while rec.path is None and time.monotonic() < deadline:
            time.sleep(0.01)  # the writer thread opens the file
        disk.gate.clear()
        c.ask("demo:lamp.on=(1)")
        assert disk.blocked.wait(10)  # the writer is stuck in a write
        caplog.set_level(logging.WARNING, logger="ramp")
        wall = time.monotonic()
        for k in range(100):  # 10 s of simulated time, a command and a get every 0.1 s
            c.ask(f"demo:motor.vel=({k % 50})")
            h.advance(0.1)
        assert time.monotonic() - wall < 20  # (it would hang if the tick waited)
        line = c.ask("robot:robot.get=()")
        dropped = int(line.split("robot:recorder.dropped=(")[1].split(")")[0])
        assert dropped > 200 and rec.dropped >= dropped  # (its own answer may be dropped)
        assert h.sup.scheduler.stats.overruns == 0
        warnings = [r for r in caplog.records if "dropping records" in r.getMessage()]
        assert len(warnings) == 1  # one warning when the drops start
    finally:
        disk.gate.set()
        h.close()


def test_a_directory_that_cannot_be_written_leaves_the_supervisor_running(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    (tmp_path / "file").write_text("")
    caplog.set_level(logging.WARNING, logger="ramp")
    rec = Recorder(RecorderConfig(str(tmp_path / "file" / "rec")))
    h = Harness(recorder=rec)
    try:
        c = h.connect()
        assert c.ask("demo:lamp.on=(1)") == ""
        h.advance(0.5)
        deadline = time.monotonic() + 10
        while rec.dropped == 0 and time.monotonic() < deadline:
            h.advance(0.1)
            time.sleep(0.01)  # the writer thread works on the wall clock
        assert rec.dropped > 0 and rec.path is None
        assert c.ask("demo:demo.get=()") == "demo:motor.vel=(0)demo:lamp.on=(1)"
        assert f"robot:recorder.dropped=({rec.dropped})" in c.ask("robot:robot.get=()")
    finally:
        h.close()
    warned = [r.getMessage() for r in caplog.records if "cannot write" in r.getMessage()]
    assert len(warned) == 1 and "file/rec" in warned[0] and "Not a directory" in warned[0]


class Counting(Observer):
    def __init__(self) -> None:
        self.commands: list[tuple[str, float]] = []
        self.started_with: Supervisor | None = None

    def started(self, supervisor: Supervisor) -> None:
        self.started_with = supervisor

    def command(self, t: float, bus: str, channel: str, value: float) -> None:
        self.commands.append((channel, value))


class Ticking(Observer):
    def __init__(self) -> None:
        self.ticks = 0

    def tick(self, t: float, late_s: float) -> None:
        self.ticks += 1


def test_fan_out_calls_each_observer_only_at_its_own_points() -> None:
    a, b = Counting(), Ticking()
    assert fan_out() is None and fan_out(None, a) is a
    both = fan_out(a, None, b)
    assert isinstance(both, FanOut)
    assert overridden(both, "command") and overridden(both, "tick")
    assert not overridden(both, "message_in")  # nobody observes it: left unconnected
    h = Harness(observer=both)
    try:
        assert h.sup.server.on_message_in is None and h.sup.scheduler.on_tick is not None
        c = h.connect()
        assert c.ask("demo:motor.vel=(40)") == ""
        h.advance(0.2)
        assert a.started_with is h.sup and ("demo.motor", 0.4) in a.commands
        assert b.ticks >= 19
    finally:
        h.close()


def test_the_recorder_and_another_observer_both_see_a_run(tmp_path: Path) -> None:
    other = Counting()
    rec = Recorder(RecorderConfig(str(tmp_path / "rec")))
    h = Harness(observer=other, recorder=rec)
    try:
        c = h.connect()
        assert c.ask("demo:motor.vel=(40)") == ""
        h.advance(0.3)
        h.world.unplugged.add("io2")  # the arm's bus goes away
        h.advance(0.1)
    finally:
        h.close()
    assert ("demo.motor", 0.4) in other.commands
    from ramp.recorder.reading import Recording

    msgs = list(Recording(sorted((tmp_path / "rec").glob("*.mcap"))))
    assert any(m.topic == "/robot/commands" and m.data["duty"] == 0.4 for m in msgs)
    assert sum(m.topic == "/demo/get" for m in msgs) >= 3  # 10 Hz over 0.3 s
    states = [(m.data["module"], m.data["state"]) for m in msgs
              if m.topic == "/robot/module_state"]
    assert states == [("demo", "ok"), ("arm", "ok"), ("arm", "fault")]
    events = [(m.data["kind"], m.data["text"]) for m in msgs if m.topic == "/robot/events"]
    assert ("fault", "bus io2: simulated device unplugged") in events
    assert ("watchdog", "armed: motion") in events


def test_recording_off_connects_no_hook_and_never_loads_the_mcap_writer() -> None:
    """`ramp run` without a recorder: the observer hooks stay None and neither the recorder
    nor the MCAP library is imported (it is only imported when recording)."""
    code = (
        "import sys\n"
        "from tests.harness import Harness\n"
        "h = Harness()\n"
        "c = h.connect(); c.ask('demo:motor.vel=(10)'); h.advance(0.2)\n"
        "sup = h.sup\n"
        "assert sup.recorder is None and sup.observer is None\n"
        "assert sup.server.on_message_in is None and sup.scheduler.on_tick is None\n"
        "assert all(b.on_command is None for b in sup.buses.values())\n"
        "assert 'recorder' not in c.ask('robot:robot.get=()')\n"
        "assert 'recorder' not in c.ask('robot:robot.describe=()')\n"
        "h.close()\n"
        "loaded = [m for m in ('mcap', 'mcap.writer', 'ramp.recorder.recorder',\n"
        "                      'ramp.recorder.writer') if m in sys.modules]\n"
        "assert not loaded, loaded\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_shutdown_closes_the_recorder_after_the_motors_stopped(tmp_path: Path) -> None:
    rec = Recorder(RecorderConfig(str(tmp_path / "rec")))
    h = Harness(DEMO_YAML, recorder=rec)
    c = h.connect()
    assert c.ask("demo:motor.vel=(70)") == ""
    h.advance(0.1)
    h.close()
    h.sup.shutdown()  # idempotent
    assert not rec.recording
    from ramp.recorder.reading import Recording

    recording = Recording(sorted((tmp_path / "rec").glob("*.mcap")))
    msgs = list(recording)
    assert recording.files[0].complete  # closed with its index
    last = [m.data for m in msgs if m.topic == "/robot/commands"
            and m.data["channel"] == "demo.motor"][-1]
    assert last["duty"] == 0.0  # the shutdown's stop is in the file
