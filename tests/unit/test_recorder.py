"""The flight recorder's files, read back with the `mcap` reader: channels and schemas, MCP
lines in order, 10 Hz sampling on the scheduler, the time mapping, rotation and `keep`,
drops behind a disk that blocks or fills, and files cut short."""

from __future__ import annotations

import errno
import io
import json
import logging
import threading
import time
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from mcap.reader import make_reader

from ramp.clock import VirtualClock
from ramp.errors import ConfigError
from ramp.mcp.messages import Response
from ramp.recorder import RECORDER_FIELDS, ChannelSpec, Recorder, RecorderConfig, RecorderError
from ramp.recorder.reading import NotMcap, Recording
from ramp.recorder.schemas import FIXED_CHANNELS
from ramp.recorder.writer import TimeBase, recording_files
from ramp.scheduler import Scheduler
from ramp.schema import apply_fields

ORIGIN = 1_779_285_600_000_000_000  # 2026-05-20 14:00:00 UTC


def read_file(path: Path) -> dict[str, Any]:
    """Schemas, channels and messages (file order) of a finished file, via its index."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None, f"{path} has no summary: not closed properly"
        msgs = [(ch.topic, m.log_time, m.sequence, json.loads(m.data), schema)
                for schema, ch, m in reader.iter_messages(log_time_order=False)]
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return {"summary": summary, "messages": msgs, "metadata": metadata}


def health_rows(uptime: float, state: str = "armed", owner: str = "none") -> list[Response]:
    return [Response("robot", "robot", "uptime", (uptime,)),
            Response("robot", "tick", "rate", (100.0,)),
            Response("robot", "tick", "late", (120, 300, 900)),
            Response("robot", "tick", "overruns", (0,)),
            Response("robot", "watchdog", "state", (state,)),
            Response("robot", "control", "owner", (owner,)),
            Response("robot", "base", "state", ("ok",))]


BASE_ROWS = [Response("base", "lf_wheel", "vel", (40,)),
             Response("base", "battery", "volt", (24.5,)),
             Response("base", "l_button", "press", (0,))]


def recorder(tmp_path: Path, **kw: Any) -> Recorder:
    cfg = kw.pop("config", None) or RecorderConfig(str(tmp_path / "rec"))
    return Recorder(cfg, origin_ns=ORIGIN, **kw)


def test_every_channel_is_present_with_a_valid_schema_and_valid_messages(
        tmp_path: Path) -> None:
    rec = recorder(tmp_path)
    clock = VirtualClock(50.0)
    rec.start(clock.now())
    logger = logging.getLogger("ramp.test_recorder")
    handler = rec.log_handler(clock.now)
    logger.addHandler(handler)
    try:
        rec.mcp_in(50.1, "127.0.0.1:40000", b"base:base.drive=(60,0)")
        rec.mcp_out(50.1, "127.0.0.1:40000", b"\n")
        rec.health(50.2, health_rows(0.2))
        rec.module_rows(50.2, "base", BASE_ROWS)
        rec.command(50.1, "base_motors", "base.lf_wheel", 0.6)
        rec.module_state(50.3, "ble", "fault", "bus ble_motors: read error")
        rec.event(50.4, "watchdog_trip", "operator silent for 1.00 s")
        clock.advance(0.5)
        logger.warning("bus %s fault: %s", "ble_motors", "gone")
        logger.info("not recorded: below WARNING")
    finally:
        logger.removeHandler(handler)
        rec.close()
    files = recording_files(tmp_path / "rec")
    assert len(files) == 1
    got = read_file(files[0][1])
    summary = got["summary"]
    topics = {ch.topic for ch in summary.channels.values()}
    assert topics == {s.topic for s in FIXED_CHANNELS} | {"/robot/get", "/base/get"}
    for ch in summary.channels.values():
        schema = summary.schemas[ch.schema_id]
        assert ch.message_encoding == "json" and schema.encoding == "jsonschema"
        doc = json.loads(schema.data)
        jsonschema.validators.validator_for(doc).check_schema(doc)
        assert doc["title"] == schema.name
    # Foxglove's reader (@mcap/core) refuses a chunk index without message indexes.
    assert summary.chunk_indexes
    assert all(ci.message_index_offsets for ci in summary.chunk_indexes)
    seen = set()
    for topic, _, _, data, schema in got["messages"]:
        jsonschema.validate(data, json.loads(schema.data))
        seen.add(topic)
    assert seen == topics
    by_topic = {topic: data for topic, _, _, data, _ in got["messages"]}
    assert by_topic["/robot/get"]["tick"]["late"] == [120, 300, 900]
    assert by_topic["/base/get"] == {"lf_wheel": {"vel": 40}, "battery": {"volt": 24.5},
                                     "l_button": {"press": 0}}
    assert by_topic["/robot/commands"] == {"bus": "base_motors", "channel": "base.lf_wheel",
                                           "duty": 0.6, "kind": "motor"}
    log = by_topic["/log"]
    assert log["level"] == 3 and log["message"] == "bus ble_motors fault: gone"
    assert log["name"] == "ramp.test_recorder" and log["line"] > 0
    assert log["timestamp"] == {"sec": ORIGIN // 10**9, "nsec": 500_000_000}
    assert summary.schemas[[c for c in summary.channels.values()
                            if c.topic == "/log"][0].schema_id].name == "foxglove.Log"


def test_mcp_lines_keep_their_order_clients_and_times(tmp_path: Path) -> None:
    rec = recorder(tmp_path)
    rec.start(1000.0)
    sent = []
    for i in range(300):
        t = 1000.0 + i * 0.003
        client = f"10.0.0.{1 + i % 3}:5{i % 3}000"
        line = f"base:lf_wheel.vel=({i % 100})"
        rec.mcp_in(t, client, line.encode())
        rec.mcp_out(t + 0.001, client, b"\n")
        sent.append((client, line, t))
    rec.mcp_in(1001.0, "10.0.0.9:1", b"bad \xff byte")
    rec.close()
    got = read_file(recording_files(tmp_path / "rec")[0][1])
    ins = [(d["client"], d["line"], ns, seq) for topic, ns, seq, d, _ in got["messages"]
           if topic == "/mcp/in"]
    assert [(c, line) for c, line, _, _ in ins[:300]] == [(c, line) for c, line, _ in sent]
    assert ins[-1][1] == "bad \\xff byte"
    assert [seq for *_, seq in ins] == list(range(1, 302))
    tb = TimeBase(1000.0, ORIGIN)
    assert [ns for _, _, ns, _ in ins[:300]] == [tb.ns(t) for *_, t in sent]
    outs = [(ns, d) for topic, ns, _, d, _ in got["messages"] if topic == "/mcp/out"]
    assert len(outs) == 300 and all(d["line"] == "" for _, d in outs)
    meta = got["metadata"]["ramp"]
    assert float(meta["clock_t0_s"]) == 1000.0 and int(meta["clock_origin_ns"]) == ORIGIN


def test_time_mapping_is_origin_plus_supervisor_seconds() -> None:
    tb = TimeBase(12.5, ORIGIN)
    assert tb.ns(12.5) == ORIGIN
    assert tb.ns(13.75) == ORIGIN + 1_250_000_000
    assert tb.seconds(tb.ns(99.123456789)) == pytest.approx(99.123456789, abs=1e-9)
    assert tb.ns(-1e12) == 0  # never a negative log time


def test_health_and_get_rows_are_sampled_at_10_hz_by_a_scheduler_task(tmp_path: Path) -> None:
    clock = VirtualClock()
    sched = Scheduler(clock, 100.0)
    rec = recorder(tmp_path)
    rec.start(clock.now())
    rec.add_rows_source("robot", lambda: health_rows(clock.now()))
    rec.add_rows_source("base", lambda: BASE_ROWS)
    rec.add_rows_source("ble", lambda: [])  # detached: nothing recorded
    sched.add_task("recorder", 10.0, rec.tick)
    sched.run_for(20.0)
    rec.close()
    got = read_file(recording_files(tmp_path / "rec")[0][1])
    for topic in ("/robot/get", "/base/get"):
        times = [ns for tp, ns, *_ in got["messages"] if tp == topic]
        assert 199 <= len(times) <= 201
        gaps = [(b - a) / 1e9 for a, b in zip(times, times[1:], strict=False)]
        assert all(0.09 <= g <= 0.11 for g in gaps), (min(gaps), max(gaps))
    assert not any(tp == "/ble/get" for tp, *_ in got["messages"])


def test_files_rotate_at_max_mb_and_only_the_newest_keep_remain(tmp_path: Path) -> None:
    cfg = RecorderConfig(str(tmp_path / "rec"), max_mb=0.02, keep=3)
    rec = Recorder(cfg, origin_ns=ORIGIN, compression="none", flush_s=0.05)
    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "notes.txt").write_text("not ours: never deleted")
    rec.start(0.0)
    for i in range(2000):  # about 200 kB in the file: ten files' worth
        rec.command(i * 0.01, "base_motors", "base.lf_wheel", (i % 200 - 100) / 100)
    rec.close()
    assert rec.dropped == 0
    files = recording_files(tmp_path / "rec")
    indices = [i for i, _ in files]
    assert len(files) == 3 and indices == list(range(indices[0], indices[0] + 3))
    assert indices[0] >= 5  # several older files were made and removed
    assert (tmp_path / "rec" / "notes.txt").exists()
    seqs = []
    for _, path in files:
        # one chunk (an eighth) past the limit, plus the index, which repeats the schemas
        assert path.stat().st_size <= 1.125 * cfg.max_bytes + 6000
        got = read_file(path)
        seqs += [seq for tp, _, seq, *_ in got["messages"] if tp == "/robot/commands"]
        # every file names every channel, even those it holds no message of
        assert {c.topic for c in got["summary"].channels.values()} >= {
            s.topic for s in FIXED_CHANNELS}
    assert seqs == list(range(seqs[0], 2001))  # the newest records, none missing


def test_a_new_run_continues_the_file_numbering(tmp_path: Path) -> None:
    for _ in range(2):
        rec = recorder(tmp_path)
        rec.start(0.0)
        rec.event(0.0, "note", "hello")
        rec.close()
    assert [i for i, _ in recording_files(tmp_path / "rec")] == [1, 2]


class GatedFile(io.BytesIO):
    """A disk that takes writes until the gate closes, then blocks until it opens."""

    def __init__(self) -> None:
        super().__init__()
        self.gate = threading.Event()
        self.gate.set()
        self.waiting = threading.Event()

    def write(self, data: Any) -> int:
        if not self.gate.is_set():
            self.waiting.set()
            self.gate.wait(30)
        return super().write(data)

    def close(self) -> None:
        self.final = self.getvalue()
        super().close()


def test_a_blocked_disk_makes_the_tick_drop_and_count_records_never_wait(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    files: list[GatedFile] = []

    def opener(path: Path) -> GatedFile:
        files.append(GatedFile())
        return files[-1]

    rec = recorder(tmp_path, opener=opener, queue_records=100, flush_s=0.01)
    rec.start(0.0)
    files[0].gate.clear()
    rec.event(0.0, "note", "first")          # the writer takes it and blocks writing it
    assert files[0].waiting.wait(10)
    caplog.set_level(logging.WARNING, logger="ramp.recorder")
    for i in range(1000):                    # a blocked disk: none of these may wait
        rec.command(0.01 * i, "base_motors", "base.lf_wheel", 0.5)
    assert rec.dropped == 900 and rec.queued == 100
    warnings = [r for r in caplog.records if "dropping records" in r.getMessage()]
    assert len(warnings) == 1
    files[0].gate.set()
    rec.close()
    data = io.BytesIO(files[0].final)
    reader = make_reader(data)
    commands = [m for _, ch, m in reader.iter_messages() if ch.topic == "/robot/commands"]
    assert len(commands) == 100
    meta = {m.name: m.metadata for m in make_reader(io.BytesIO(files[0].final)).iter_metadata()}
    assert meta["ramp.recorder"]["dropped"] == "900"


def test_a_queue_full_of_bytes_drops_too(tmp_path: Path) -> None:
    files: list[GatedFile] = []

    def opener(path: Path) -> GatedFile:
        files.append(GatedFile())
        return files[-1]

    rec = recorder(tmp_path, opener=opener, queue_bytes=10_000, flush_s=0.01)
    rec.start(0.0)
    files[0].gate.clear()
    rec.event(0.0, "note", "first")
    assert files[0].waiting.wait(10)
    for _ in range(20):
        rec.mcp_out(0.0, "c", "x" * 1000)
    assert rec.queued == 9 and rec.dropped == 11
    files[0].gate.set()
    rec.close()


class FullDisk(io.BytesIO):
    """A disk that fills up after `room` bytes until `room` is raised."""

    def __init__(self, room: list[int]) -> None:
        super().__init__()
        self.room = room

    def write(self, data: Any) -> int:
        if self.tell() + len(data) > self.room[0]:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)

    def close(self) -> None:
        self.final = self.getvalue()
        super().close()


def test_a_full_disk_is_reported_once_drops_are_counted_and_recording_resumes(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    room = [10**9]
    files: list[FullDisk] = []

    def opener(path: Path) -> FullDisk:
        files.append(FullDisk(room))
        return files[-1]

    caplog.set_level(logging.WARNING, logger="ramp.recorder")
    rec = recorder(tmp_path, opener=opener, flush_s=0.01, retry_s=0.2, compression="none")
    rec.start(0.0)
    room[0] = files[0].tell() + 500  # the disk fills up a few records after the start
    for i in range(200):
        rec.command(i * 0.01, "base_motors", "base.lf_wheel", 0.1)
        time.sleep(0.001)
    deadline = time.monotonic() + 10
    while rec.dropped == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert rec.dropped > 0
    full = [r for r in caplog.records if "No space left on device" in r.getMessage()]
    assert len(full) == 1 and "records are dropped" in full[0].getMessage()
    room[0] = 10**9  # space freed
    time.sleep(0.3)  # past retry_s: the next record opens a new file
    rec.event(5.0, "note", "after the disk was freed")
    rec.close()
    last = make_reader(io.BytesIO(files[-1].final))
    notes = [json.loads(m.data) for _, ch, m in last.iter_messages() if ch.topic == "/robot/events"]
    assert notes == [{"kind": "note", "text": "after the disk was freed"}]
    assert len(files) >= 2


def test_a_file_cut_anywhere_reads_up_to_its_last_whole_chunk(tmp_path: Path) -> None:
    rec = recorder(tmp_path, flush_s=0.01)
    rec.start(0.0)
    for i in range(10):
        for k in range(50):
            rec.command(i + k * 0.01, "base_motors", "base.lf_wheel", k / 100)
        time.sleep(0.05)  # one chunk or more per batch
    rec.close()
    path = recording_files(tmp_path / "rec")[0][1]
    data = path.read_bytes()
    whole = [m.data for m in Recording([path])]
    assert len(whole) == 500
    counts = []
    for cut in range(40, len(data), max(1, len(data) // 60)):
        part = tmp_path / f"cut-{cut}.mcap"
        part.write_bytes(data[:cut])
        rec_read = Recording([part])
        got = [m.data for m in rec_read]
        assert got == whole[:len(got)]  # a prefix, never garbage
        assert rec_read.files[0].truncated and not rec_read.files[0].complete
        counts.append(len(got))
    assert counts == sorted(counts) and counts[-1] >= 450


def test_a_file_that_is_not_mcap_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "x.mcap"
    bad.write_text("hello, not a recording")
    with pytest.raises(NotMcap):
        list(Recording([bad]))


def test_more_channels_are_declared_then_published(tmp_path: Path) -> None:
    pose = ChannelSpec("/autonomy/pose", "foxglove.PoseInFrame", {
        "title": "foxglove.PoseInFrame", "type": "object",
        "properties": {"frame_id": {"type": "string"}}})
    rec = recorder(tmp_path)
    rec.add_channel(pose)
    with pytest.raises(KeyError):
        rec.publish(0.0, "/autonomy/scan", {})
    with pytest.raises(ValueError, match="already declared"):
        rec.add_channel(ChannelSpec("/autonomy/pose", "other", {}))
    rec.start(0.0)
    rec.publish(0.5, "/autonomy/pose", {"frame_id": "arena"})
    rec.close()
    got = read_file(recording_files(tmp_path / "rec")[0][1])
    assert [(tp, d) for tp, _, _, d, _ in got["messages"]] == [
        ("/autonomy/pose", {"frame_id": "arena"})]


def test_nothing_is_recorded_before_start_or_after_close(tmp_path: Path) -> None:
    rec = recorder(tmp_path)
    rec.event(0.0, "note", "too early")
    assert rec.queued == 0
    rec.start(0.0)
    rec.close()
    rec.close()  # idempotent
    rec.event(1.0, "note", "too late")
    assert rec.queued == 0 and rec.dropped == 0


def test_an_unwritable_directory_fails_at_start_with_the_reason(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    rec = Recorder(RecorderConfig(str(blocker / "rec")))
    with pytest.raises(RecorderError, match=r"cannot write to .*file/rec"):
        rec.start(0.0)


def test_config_block_is_checked_with_key_paths() -> None:
    cfg = RecorderConfig.from_mapping({"dir": "/var/lib/ramp/rec"})
    assert (cfg.max_mb, cfg.keep, cfg.max_bytes) == (100.0, 20, 100_000_000)
    assert apply_fields(RECORDER_FIELDS, {"dir": "d", "max_mb": 5})["max_mb"] == 5.0
    assert isinstance(RecorderConfig("d", max_mb=5).max_mb, float)
    with pytest.raises(ConfigError, match=r"recorder\.keep: 0 is not how many files"):
        RecorderConfig.from_mapping({"dir": "d", "keep": 0})
    with pytest.raises(ConfigError, match=r"recorder\.dir: missing"):
        RecorderConfig.from_mapping({"max_mb": 5})
    with pytest.raises(ConfigError, match=r"recorder\.size: unknown key"):
        RecorderConfig.from_mapping({"dir": "d", "size": 5})
    with pytest.raises(ConfigError, match=r"recorder\.max_mb: -1"):
        RecorderConfig("d", max_mb=-1)
    with pytest.raises(ConfigError, match=r"recorder\.dir"):
        RecorderConfig("  ")


def test_a_run_that_ends_just_after_a_rotation_leaves_no_empty_file(tmp_path: Path) -> None:
    from ramp.recorder.writer import SegmentWriter

    channels = {s.topic: s for s in FIXED_CHANNELS}
    seg = SegmentWriter(tmp_path, 4000, 10, TimeBase(0.0, ORIGIN), channels,
                        compression="none")
    seg.open_next()
    topic = FIXED_CHANNELS[0].topic
    t = 0.0
    first = seg.path
    for _ in range(1000):  # fill the file until the flush that rotates it
        t += 0.01
        seg.write(topic, t, b'{"x": "' + b"y" * 200 + b'"}')
        seg.flush(sync=False)
        if not seg.is_open or seg.path != first:
            break
    seg.finish()  # the run ends here, before another record arrives
    files = recording_files(tmp_path)
    assert len(files) == 1
    assert read_file(files[0][1])["messages"]
