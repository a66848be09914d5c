"""The flight recorder: what the supervisor calls to record a run (SPEC section 8).

The methods the tick calls (`mcp_in`, `mcp_out`, `health`, `module_rows`, `command`,
`module_state`, `event`, `publish`) only encode one JSON payload and append it to a bounded
queue: a few microseconds each (`python -m bench --only recorder`), never a wait. The writer
thread (`ramp.recorder.writer`) puts the records into MCAP files. When it falls behind (a slow
or full disk) the queue fills and new records are dropped and counted in `dropped`; the first
drop of an episode logs one warning.

Times are the supervisor's clock in seconds (the `now` its tasks receive); see
`writer.TimeBase` for how they become MCAP log times.

The supervisor does all of this itself when given a recorder (`ramp run --record DIR`,
`ramp.runtime.build(..., recorder=rec)`: see `ramp.runtime.recording`). By hand::

    rec = Recorder(RecorderConfig("/var/lib/ramp/rec"))
    rec.start(clock.now())
    rec.add_rows_source("robot", robot_get_rows)          # sampled by rec.tick
    rec.add_rows_source("base", base_get_rows)
    scheduler.add_task("recorder", SAMPLE_HZ, rec.tick)   # 10 Hz
    logging.getLogger("ramp").addHandler(rec.log_handler(clock.now))
    ...
    rec.mcp_in(now, conn.peer, line)                      # wherever the events happen
    ...
    rec.close()                                           # at shutdown: indexes the file
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

from ramp.errors import RampError
from ramp.recorder.config import RecorderConfig
from ramp.recorder.jsonbytes import json_payload
from ramp.recorder.schemas import (
    EVENT_KINDS,
    FIXED_CHANNELS,
    TOPIC_COMMANDS,
    TOPIC_EVENTS,
    TOPIC_HEALTH,
    TOPIC_LOG,
    TOPIC_MCP_IN,
    TOPIC_MCP_OUT,
    TOPIC_MODULE_STATE,
    ChannelSpec,
    module_topic,
    rows_schema,
)
from ramp.recorder.writer import Opener, Record, SegmentWriter, TimeBase, WriterThread

log = logging.getLogger("ramp.recorder")

#: How often `tick` should run (the scheduler task's rate): health and get rows at 10 Hz.
SAMPLE_HZ = 10.0
#: A drop after the queue had emptied logs again, but not more often than this (s).
DROP_WARNING_INTERVAL_S = 60.0



class Row(Protocol):
    """A get row, as `ramp.mcp.messages.Response`: `MODULE:DEVICE.PROP=(values)`."""

    @property
    def device(self) -> str: ...
    @property
    def prop(self) -> str: ...
    @property
    def values(self) -> tuple[Any, ...]: ...


RowsSource = Callable[[], Sequence[Row]]


class RecorderError(RampError):
    """The recorder cannot start (its directory cannot be made or written)."""


class Recorder:
    """Records a run into rotating MCAP files; cheap to call from the tick.

    `origin_ns`: the wall clock (ns since the epoch) at `start` (default: read then; tests
    pass one so files repeat). `opener`: opens each new file (tests pass slow or failing
    ones). `queue_records`/`queue_bytes`: what may wait for the writer before records are
    dropped (20,000 records is about 14 s of a busy run). `flush_s`: the longest a record
    waits in an open chunk. `retry_s`: after a write error, when a new file is tried.
    `session`: extra key-values for each file's `ramp` metadata record.
    """

    def __init__(self, config: RecorderConfig, *, origin_ns: int | None = None,
                 opener: Opener | None = None, queue_records: int = 20_000,
                 queue_bytes: int = 16 << 20, flush_s: float = 0.5, retry_s: float = 5.0,
                 compression: str = "zstd", session: Mapping[str, str] | None = None) -> None:
        self.config = config
        self.queue_records = queue_records
        self.queue_bytes = queue_bytes
        self._origin_ns = origin_ns
        self._opener = opener
        self._flush_s = flush_s
        self._retry_s = retry_s
        self._compression = compression
        self._session = dict(session or {})
        self._queue: deque[Record] = deque()
        self._lock = threading.Lock()  # producers only (tick, log handler on any thread)
        self._bytes_in = 0
        self._dropped_full = 0
        self._warned_at: float | None = None
        self._channels: dict[str, ChannelSpec] = {s.topic: s for s in FIXED_CHANNELS}
        self._sources: dict[str, RowsSource] = {}
        self._segments: SegmentWriter | None = None
        self._thread: WriterThread | None = None
        self._dropping = False
        self.timebase: TimeBase | None = None
        #: True between `start` and `close`: the tick's calls record (else they do nothing).
        self.recording = False

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self, now: float, *, wait_for_file: bool = True) -> None:
        """Start the writer. With `wait_for_file`, the first file is opened here (raises
        RecorderError if it cannot be); without, the writer thread opens it, so a slow disk
        never holds the caller (the supervisor's start-up), and a directory it cannot
        write is logged once and retried every `retry_s` while records are dropped and
        counted."""
        if self._thread is not None:
            return  # started once: a recorder is not restarted
        origin = self._origin_ns if self._origin_ns is not None else time.time_ns()
        self.timebase = TimeBase(now, origin)
        kwargs = {"opener": self._opener} if self._opener is not None else {}
        self._segments = SegmentWriter(
            Path(self.config.dir), self.config.max_bytes, self.config.keep, self.timebase,
            self._channels, compression=self._compression, session=self._session, **kwargs)
        if wait_for_file:
            try:
                self._segments.open_next()
            except OSError as exc:
                raise RecorderError(f"recorder: cannot write to {self.config.dir}: "
                                    f"{exc.strerror or exc}") from exc
            self._segments.announce()
        self._thread = WriterThread(self._queue, self._segments, flush_s=self._flush_s,
                                    retry_s=self._retry_s, final_metadata=self._final_metadata)
        self.recording = True
        self._thread.start()

    def close(self, timeout: float = 5.0) -> None:
        """Write what is queued, index and close the file. Idempotent.

        Waits at most `timeout` s for the writer (a hung disk must not hang the shutdown);
        what it has not written by then is lost, and the file stays readable without its
        index.
        """
        was_recording, self.recording = self.recording, False
        thread = self._thread
        if thread is None or not was_recording:
            return
        thread.stop()
        thread.join(timeout)
        if thread.is_alive():
            log.error("recorder: the disk did not take the last records within %.0f s; "
                      "%s is left without its index", timeout,
                      self._segments.path if self._segments else "the file")

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- figures ------------------------------------------------------------------------------
    @property
    def dropped(self) -> int:
        """Records lost: the queue was full (slow disk), the disk refused them, or they went
        into a file deleted under the recorder."""
        io = self._thread.lost if self._thread is not None else 0
        return self._dropped_full + io

    @property
    def written(self) -> int:
        """Records handed to the MCAP writer (in the current and earlier files)."""
        return self._segments.written if self._segments is not None else 0

    @property
    def queued(self) -> int:
        return len(self._queue)

    @property
    def path(self) -> Path | None:
        """The file being written now."""
        return self._segments.path if self._segments is not None else None

    def _final_metadata(self) -> dict[str, str]:
        """Written into the last file as it is closed (`ramp log summary` reports it)."""
        return {"dropped": str(self.dropped), "written": str(self.written)}

    # -- the tick's calls ---------------------------------------------------------------------
    def mcp_in(self, t: float, client: str, line: bytes | str) -> None:
        """An MCP message as it arrived (without its `\\n`; a heartbeat is empty)."""
        if self.recording:
            self._put(TOPIC_MCP_IN, t, json_payload({"client": client, "line": _text(line)}))

    def mcp_out(self, t: float, client: str, line: bytes | str) -> None:
        """The response line sent for a message (its trailing `\\n` is left out)."""
        if self.recording:
            self._put(TOPIC_MCP_OUT, t, json_payload({"client": client, "line": _text(line)}))

    def health(self, t: float, rows: Iterable[Row]) -> None:
        """`robot.get`'s rows (the supervisor's health)."""
        self.module_rows(t, "robot", rows)

    def module_rows(self, t: float, module: str, rows: Iterable[Row]) -> None:
        """A module's get rows, as `{device: {property: value}}` on `/MODULE/get`."""
        if not self.recording:
            return
        data = rows_dict(rows)
        if not data:
            return
        topic = TOPIC_HEALTH if module == "robot" else module_topic(module)
        if topic not in self._channels:
            self._channels[topic] = ChannelSpec(topic, f"ramp.{module}.get",
                                                rows_schema(module, data))
        self._put(topic, t, json_payload(data))

    def command(self, t: float, bus: str, channel: str, duty: float,
                kind: str = "motor") -> None:
        """A command handed to a driver: `channel` is the device as `module.device`; `kind`
        is `motor` (a duty -1..1) or `output` (a digital output, 0 or 1)."""
        if self.recording:
            self._put(TOPIC_COMMANDS, t, json_payload({"bus": bus, "channel": channel,
                                                   "duty": duty, "kind": kind}))

    def module_state(self, t: float, module: str, state: str, reason: str = "") -> None:
        """A module went to `ok`, `fault` or `detached`."""
        if self.recording:
            self._put(TOPIC_MODULE_STATE, t, json_payload({"module": module, "state": state,
                                                       "reason": reason}))

    def event(self, t: float, kind: str, text: str) -> None:
        """A supervisor event; `kind` is one of `schemas.EVENT_KINDS` (else `note`)."""
        if self.recording:
            if kind not in EVENT_KINDS:
                text, kind = f"{kind}: {text}", "note"
            self._put(TOPIC_EVENTS, t, json_payload({"kind": kind, "text": text}))

    def log(self, t: float, level: int, message: str, name: str, file: str, line: int) -> None:
        """A log record as `foxglove.Log` (`level` in Foxglove's numbers, 3 = WARNING)."""
        if not self.recording or self.timebase is None:
            return
        sec, nsec = divmod(self.timebase.ns(t), 1_000_000_000)
        self._put(TOPIC_LOG, t, json_payload({
            "timestamp": {"sec": sec, "nsec": nsec}, "level": level, "message": message,
            "name": name, "file": file, "line": max(0, line)}))

    # -- more channels ------------------------------------------------------------------------
    def add_channel(self, spec: ChannelSpec) -> None:
        """Declare a channel (a Foxglove schema, say) before `publish`ing on it."""
        if spec.topic in self._channels and self._channels[spec.topic] != spec:
            raise ValueError(f"recorder: topic {spec.topic} is already declared otherwise")
        self._channels[spec.topic] = spec

    def publish(self, t: float, topic: str, payload: Mapping[str, Any]) -> None:
        """Record a payload on a declared channel (`add_channel`)."""
        if topic not in self._channels:
            raise KeyError(f"recorder: no channel {topic}; declare it with add_channel")
        if self.recording:
            self._put(topic, t, json_payload(payload))

    # -- periodic sampling --------------------------------------------------------------------
    def add_rows_source(self, module: str, rows: RowsSource) -> None:
        """`rows()` is sampled by `tick` (10 Hz): `robot` for health, else a module's get.
        A source returns no rows while its module is not attached."""
        self._sources[module] = rows

    def tick(self, now: float, dt: float) -> None:
        """Scheduler task at SAMPLE_HZ: one sample of every rows source."""
        if not self.recording:
            return
        for module, rows in self._sources.items():
            try:
                sample = rows()
            except Exception:  # noqa: BLE001 - recording must never stop the tick
                log.exception("recorder: cannot sample %s", module)
                continue
            self.module_rows(now, module, sample)

    def log_handler(self, now: Callable[[], float],
                    level: int = logging.WARNING) -> logging.Handler:
        """A logging handler recording WARNING and above on `/log` (`now`: the supervisor's
        clock)."""
        from ramp.recorder.loghandler import RecorderLogHandler

        return RecorderLogHandler(self, now, level)

    # -- the queue ----------------------------------------------------------------------------
    def _put(self, topic: str, t: float, payload: bytes) -> None:
        with self._lock:
            thread = self._thread
            queued = self._bytes_in - (thread.bytes_out if thread is not None else 0)
            if (len(self._queue) >= self.queue_records
                    or queued + len(payload) > self.queue_bytes):
                self._dropped_full += 1
                warn = not self._dropping and (
                    self._warned_at is None or t - self._warned_at >= DROP_WARNING_INTERVAL_S)
                self._dropping = True
                if warn:
                    self._warned_at = t
            else:
                if not self._queue:
                    self._dropping = False  # the writer caught up: the episode is over
                self._bytes_in += len(payload)
                self._queue.append((topic, t, payload))
                return
        if warn:  # one warning per episode of drops, at most one a minute
            log.warning("recorder: the disk is not keeping up; dropping records "
                        "(%d so far) rather than delaying the tick", self.dropped)


def rows_dict(rows: Iterable[Row]) -> dict[str, dict[str, Any]]:
    """Rows as `{device: {property: value}}`; several values make a list, none `null`."""
    out: dict[str, dict[str, Any]] = {}
    for r in rows:
        values = r.values
        value = values[0] if len(values) == 1 else list(values) if values else None
        props = out.get(r.device)
        if props is None:
            out[r.device] = props = {}
        props[r.prop] = value
    return out


def _text(line: bytes | str) -> str:
    if isinstance(line, bytes | bytearray | memoryview):
        line = bytes(line).decode("ascii", "backslashreplace")
    return line[:-1] if line.endswith("\n") else line


