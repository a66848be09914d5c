"""The flight recorder in real `ramp run --sim` processes on the wall clock, read back with
the `mcap` reader (SPEC 8): every channel with a valid JSON Schema, each client's MCP lines
in order, health and module get rows at 10 Hz, the commands a real Sabertooth driver put on
a pty matching the recording, a SIGKILLed recording readable and short of at most its last
second, rotation at `max_mb` with `keep` files, and a bad `recorder:` block refused.

About 15 s in all (three supervisor processes of 3-4 s each, and one config check)."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import jsonschema
import pytest
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader

from ramp.recorder.logcli import main as log_main
from ramp.recorder.writer import TimeBase, recording_files
from tests.harness import MARTE_YAML, REPO
from tests.harness import ask_line as ask

#: Where MARTE's base wheels are wired (ramp.yaml): (Sabertooth address, motor).
WHEELS = {"base.lf_wheel": (128, 1), "base.lb_wheel": (128, 2), "base.rf_wheel": (129, 1),
          "base.rb_wheel": (129, 2)}
STEP = 1 / 127  # the Sabertooth's resolution


def start(args: list[str], log: IO[bytes]) -> tuple[subprocess.Popen[bytes], int]:
    """`ramp run ARGS` with its log in `log`, once it is ready: (process, port)."""
    proc = subprocess.Popen([sys.executable, "-m", "ramp.cli", "run", "--host", "127.0.0.1",
                             "--port", "0", *args], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=log)
    assert proc.stdout is not None
    line = proc.stdout.readline().decode()
    m = re.match(r"ramp: ready on [\d.]+:(\d+)", line)
    if m is None:
        proc.kill()
        proc.wait()
        raise AssertionError(f"no ready line: {line!r}")
    return proc, int(m.group(1))


@contextlib.contextmanager
def running(args: list[str], tmp_path: Path) -> Iterator[tuple[subprocess.Popen[bytes], int]]:
    with open(tmp_path / "ramp.log", "wb") as log:
        proc, port = start(args, log)
        try:
            yield proc, port
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.wait(10)
            if proc.stdout is not None:
                proc.stdout.close()


def connect(port: int) -> socket.socket:
    s = socket.create_connection(("127.0.0.1", port), timeout=5)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def peer(s: socket.socket) -> str:
    host, port = s.getsockname()[:2]
    return f"{host}:{port}"


def read(path: Path) -> list[tuple[str, int, Any, Any]]:
    """(topic, log time, message, its channel's schema) of a closed file, in file order."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary() is not None, f"{path} was not closed with its index"
        return [(ch.topic, m.log_time, json.loads(m.data), json.loads(s.data))
                for s, ch, m in reader.iter_messages(log_time_order=False)]


# -- one recorded run, a real Sabertooth driver on a pty ----------------------------------------
class PtyController:
    """The base's two Sabertooths on a pty, serviced by a thread while the test runs; every
    duty change each motor saw, in order."""

    def __init__(self, tmp_path: Path) -> None:
        from firmware_like.pty_link import PtyLink
        from firmware_like.sabertooth import SabertoothEmulator, SabertoothPtyDevice

        self.seen: dict[tuple[int, int], list[float]] = {k: [0.0] for k in WHEELS.values()}
        self.link = PtyLink("base_motors", tmp_path)
        self.emu = SabertoothEmulator((128, 129), on_motor=self._motor)
        self.device = SabertoothPtyDevice(self.link, self.emu)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _motor(self, address: int, motor: int, duty: float) -> None:
        seen = self.seen[(address, motor)]
        if seen[-1] != duty:
            seen.append(duty)

    def _serve(self) -> None:
        while not self._stop.is_set():
            self.device.service(time.monotonic())
            time.sleep(0.002)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.device.service(time.monotonic())  # the last bytes written before the exit
        self.link.close()


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """`ramp run --sim --record DIR` with the base on a real Sabertooth driver (`sim:
    false`): an operator drives and digs, a console polls robot.get, an intruder sends a bad
    request, then takes control over; SIGTERM; then the file."""
    tmp = tmp_path_factory.mktemp("recorded")
    controller = PtyController(tmp)
    cfg = tmp / "bench.yaml"
    cfg.write_text(MARTE_YAML.replace(
        "base_motors: {driver: sabertooth, port: /dev/ttyUSB0, baud: 9600, timeout: 0.5}",
        f"base_motors: {{driver: sabertooth, port: {controller.link.path}, baud: 9600, "
        "sim: false}"))
    sent: dict[str, list[str]] = {}
    answers: dict[str, list[str]] = {}

    def say(s: socket.socket, text: str) -> str:
        sent.setdefault(peer(s), []).append(text)
        answer = ask(s, text)
        answers.setdefault(peer(s), []).append(answer)
        return answer

    try:
        with running(["--sim", "--config", str(cfg), "--record", str(tmp / "rec")],
                     tmp) as (proc, port):
            with connect(port) as operator, connect(port) as console, \
                    connect(port) as intruder:
                start = time.monotonic()
                say(operator, "robot:control.acquire=(operator)")
                plan = [(0.0, "base:base.drive=(60,0)"), (0.8, "base:base.drive=(40,30)"),
                        (1.4, "base:base.drive=(-50,0)"), (1.9, "ble:chain.vel=(70)"),
                        (2.1, "base:lf_wheel.vel=(25)"), (2.4, "base:base.stop=()"),
                        (2.6, "ble:ble.stop=()")]
                k = 0
                while (now := time.monotonic() - start) < 2.9:
                    due = [text for at, text in plan if at <= now]
                    if len(due) > k:
                        for text in due[k:]:
                            assert say(operator, text) == ""
                        k = len(due)
                    else:
                        say(operator, "")  # heartbeat
                    if int(now * 10) % 3 == 0:
                        say(console, "robot:robot.get=()")
                    time.sleep(0.05)
                say(intruder, "base:lf_wheel.vel=(300)")
                say(intruder, "ble:chain.vel=(10)")  # not the owner
                say(intruder, "robot:control.acquire=(intruder)")  # takes over: a warning
                health = say(console, "robot:robot.get=()")
                say(operator, "robot:control.release=()")
                time.sleep(0.2)
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(10) == 0
    finally:
        controller.close()
    files = recording_files(tmp / "rec")
    assert len(files) == 1
    return {"path": files[0][1], "messages": read(files[0][1]), "sent": sent,
            "answers": answers, "health": health, "wire": controller.seen,
            "log": (tmp / "ramp.log").read_text()}


def test_every_channel_is_in_the_file_with_a_valid_json_schema(run: dict[str, Any]) -> None:
    messages = run["messages"]
    topics = {tp for tp, *_ in messages}
    assert topics == {"/mcp/in", "/mcp/out", "/robot/get", "/base/get", "/ble/get",
                      "/robot/commands", "/robot/module_state", "/robot/events", "/log"}
    validators: dict[str, Any] = {}
    for topic, _, data, schema in messages:
        if topic not in validators:
            cls = jsonschema.validators.validator_for(schema)
            cls.check_schema(schema)
            validators[topic] = cls(schema)
        validators[topic].validate(data)
    logs = [d for tp, _, d, _ in messages if tp == "/log"]
    assert any("control taken over: operator -> intruder" in d["message"] and d["level"] == 3
               for d in logs)  # the log's warnings, as foxglove.Log


def test_each_clients_lines_are_recorded_in_order_with_their_answers(
        run: dict[str, Any]) -> None:
    messages = run["messages"]
    assert len(run["sent"]) == 3
    for client, lines in run["sent"].items():
        ins = [d["line"] for tp, _, d, _ in messages if tp == "/mcp/in" and d["client"] == client]
        outs = [d["line"] for tp, _, d, _ in messages
                if tp == "/mcp/out" and d["client"] == client]
        assert ins == lines
        assert outs == run["answers"][client]
    times = [t for tp, t, *_ in messages if tp == "/mcp/in"]
    assert times == sorted(times)


def test_health_and_module_rows_come_at_10_hz(run: dict[str, Any]) -> None:
    for topic in ("/robot/get", "/base/get", "/ble/get"):
        times = [t for tp, t, *_ in run["messages"] if tp == topic]
        rate = (len(times) - 1) / ((times[-1] - times[0]) / 1e9)
        assert 9.0 <= rate <= 11.0, (topic, rate)
        gaps = [(b - a) / 1e9 for a, b in zip(times, times[1:], strict=False)]
        assert sorted(gaps)[len(gaps) // 2] == pytest.approx(0.1, abs=0.01), topic
    assert "robot:recorder.dropped=(0)" in run["health"]
    last = [d for tp, _, d, _ in run["messages"] if tp == "/robot/get"][-1]
    assert last["recorder"]["dropped"] == 0 and last["base"]["state"] == "ok"


def test_the_commands_recorded_are_what_the_sabertooths_received(run: dict[str, Any]) -> None:
    recorded: dict[str, list[float]] = {label: [0.0] for label in WHEELS}
    for tp, _, d, _ in run["messages"]:
        if tp == "/robot/commands" and d["channel"] in WHEELS:
            assert d["bus"] == "base_motors" and d["kind"] == "motor"
            if recorded[d["channel"]][-1] != d["duty"]:
                recorded[d["channel"]].append(d["duty"])
    for label, where in WHEELS.items():
        wire, want = run["wire"][where], recorded[label]
        # Every value on the wire was recorded, in the same order (the newest command wins,
        # so one superseded before it went out may be missing from the wire, never the
        # reverse); and the last one is the same.
        i = 0
        for value in wire:
            while i < len(want) and abs(want[i] - value) > STEP:
                i += 1
            assert i < len(want), f"{label}: {value} reached the wire but is not in the file"
        assert len(wire) >= 4, (label, wire)  # drive, turn, reverse, stop at least
        assert abs(want[-1] - wire[-1]) <= STEP and wire[-1] == 0.0
    assert max(recorded["base.lf_wheel"]) == pytest.approx(0.6)


def test_the_summary_tells_what_happened(run: dict[str, Any],
                                         capsys: pytest.CaptureFixture[str]) -> None:
    assert log_main(["summary", str(run["path"]), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["files"][0]["complete"] and len(r["clients"]) == 3
    assert [o["owner"] for o in r["owners"]] == ["operator", "intruder"]
    # the intruder's chain command, then the operator's release once it no longer owned
    assert r["error_responses"] == {"bad_params": 1, "not_owner": 2}
    assert r["events"]["control"] == 3 and r["recorder_dropped"] == 0
    assert 2.0 <= r["motion_s"]["base"] <= 3.0
    assert r["log"]["warnings"] >= 1


# -- a recording cut by SIGKILL -----------------------------------------------------------------
@pytest.mark.timeout(60)
def test_a_sigkilled_run_leaves_a_readable_file_short_of_at_most_a_second(
        tmp_path: Path) -> None:
    with running(["--sim", "--record", str(tmp_path / "rec")], tmp_path) as (proc, port), \
            connect(port) as s:
        assert ask(s, "base:base.drive=(50,0)") == ""
        end = time.monotonic() + 2.5
        n = 0
        while time.monotonic() < end:
            assert ask(s, f"base:lf_wheel.vel=({n % 100})") == ""
            n += 1
            time.sleep(0.02)
        killed_at = time.monotonic()  # CLOCK_MONOTONIC: the supervisor's clock too
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    assert proc.returncode == -signal.SIGKILL
    (_, path), = recording_files(tmp_path / "rec")
    meta: dict[str, str] = {}
    got: list[tuple[str, int, Any]] = []
    with open(path, "rb") as f, contextlib.suppress(McapError):  # the cut may end mid-record
        for _, channel, message in NonSeekingReader(f, validate_crcs=True).iter_messages(
                log_time_order=False):
            got.append((channel.topic, message.log_time, json.loads(message.data)))
    with open(path, "rb") as f, contextlib.suppress(McapError):
        for m in NonSeekingReader(f).iter_metadata():
            meta.update(m.metadata)
    tb = TimeBase(float(meta["clock_t0_s"]), int(meta["clock_origin_ns"]))
    last = tb.seconds(max(t for _, t, _ in got))
    print(f"lost {killed_at - last:.3f} s before the kill")
    assert killed_at - last <= 1.0, f"lost {killed_at - last:.3f} s before the kill"
    lines = [d["line"] for tp, _, d in got if tp == "/mcp/in"]
    assert lines == ["base:base.drive=(50,0)"] + [f"base:lf_wheel.vel=({k % 100})"
                                                   for k in range(len(lines) - 1)]
    assert len(lines) >= 0.5 * n  # in order, none missing before the cut
    assert sum(tp == "/robot/get" for tp, _, _ in got) >= 15  # 10 Hz for 2.5 s, bar the cut


# -- rotation, from the YAML block --------------------------------------------------------------
@pytest.mark.timeout(60)
def test_files_rotate_at_max_mb_and_only_keep_files_remain(tmp_path: Path) -> None:
    cfg = tmp_path / "ramp.yaml"
    cfg.write_text(MARTE_YAML + "\nrecorder: {dir: rec, max_mb: 0.02, keep: 3}\n")
    with running(["--sim", "--config", str(cfg)], tmp_path) as (proc, port):
        with connect(port) as s:
            end = time.monotonic() + 2.5
            while time.monotonic() < end:  # base.get's answer is 180 bytes: files fill fast
                ask(s, "base:base.get=()")
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    files = recording_files(tmp_path / "rec")  # relative to the config file
    indexes = [i for i, _ in files]
    assert len(files) == 3 and indexes == list(range(indexes[0], indexes[0] + 3))
    assert indexes[0] >= 3, "no file was removed: the run did not fill keep files"
    spans = []
    for k, (_, path) in enumerate(files):
        messages = read(path)
        times = [t for _, t, *_ in messages]
        spans.append((min(times), max(times)))
        if k < len(files) - 1:  # the last one may have begun after the client's last line
            assert {tp for tp, *_ in messages} >= {"/mcp/in", "/mcp/out"}
        data = path.read_bytes()
        summary_start = struct.unpack("<Q", data[-28:-20])[0]  # the footer's first field
        if k < len(files) - 1:  # rotated: its records end past 20 kB, within one chunk
            assert 20_000 <= summary_start <= 20_000 * 1.125, (path.name, summary_start)
    assert all(a[1] <= b[0] for a, b in zip(spans, spans[1:], strict=False))  # one after another
    # one line per backlog of old files: "removed ramp-000001-..." or "removed 5 files
    # (ramp-000001-... to ...)"
    assert re.search(r"removed (\d+ files \()?ramp-000001-", (tmp_path / "ramp.log").read_text())


def test_a_bad_recorder_block_stops_ramp_run_with_file_line_and_key(tmp_path: Path) -> None:
    cfg = tmp_path / "ramp.yaml"
    cfg.write_text(MARTE_YAML + "\nrecorder:\n  dir: rec\n  max_mb: 0\n")
    proc = subprocess.run([sys.executable, "-m", "ramp.cli", "run", "--sim", "--config",
                           str(cfg)], cwd=REPO, text=True, capture_output=True, timeout=30)
    assert proc.returncode == 2
    line = MARTE_YAML.count("\n") + 4
    assert f"{cfg}:{line}: recorder.max_mb: 0 is not a file size in MB" in proc.stderr
    assert not (tmp_path / "rec").exists()
