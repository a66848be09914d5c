"""The recorder's writer thread: the only code that touches the MCAP files.

Why a thread (an I/O edge, like the stall guard): a file write can block for as long as the
disk likes (an SD card's erase cycle, a full disk, an NFS mount gone away), and nothing that
blocks may run on the tick. The tick only appends encoded records to a bounded deque
(`Recorder._put`); this thread drains it, frames the records into MCAP chunks, compresses and
writes them. If this thread falls behind, the deque fills and the tick drops new records (and
counts them) instead of waiting.

Why it reads `time.monotonic()`: chunks are closed on the writer's own wall-clock period
(`flush_s`, 0.5 s), whatever clock the supervisor runs on, and then `fdatasync`ed, so a file
cut by SIGKILL or a power loss keeps everything but the last second: the MCAP reader reads a
file without its footer up to its last whole chunk. A chunk is also closed (written, not
synced) when it reaches `CHUNK_BYTES`.

The GIL: this thread's Python work (MCAP framing) holds the interpreter lock, and the tick
thread waking from `select` must wait for it. So the thread works in short slices
(`SLICE_RECORDS`) with a real pause between them, and chunks stay small (mcap-python writes
a chunk's message index in one Python loop); compression, checksums and writes run in C.
The directory is scanned once, in slices (`SCAN_SLICE` entries), and the recorder keeps the
list of its own files from then on: a rotation costs the same in a directory of 50,000 files
as in an empty one, and old files are pruned between records, a few at a time
(`PRUNE_SLICE`), with one log line per backlog, not one per file.

What can go wrong is counted, never fatal: a record that cannot be written (a full disk, a
directory that cannot be made) is counted in `dropped_io` and retried every `retry_s`, one
warning per episode; any other exception is handled the same way (the thread never dies
with records still coming). The file being written is checked on every timed flush: deleted
or replaced under us (its path is gone, or names another inode), it is abandoned
with a warning, the records written into it since the last check are counted as lost, and
the next record starts a new file.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import io
import logging
import os
import re
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

from mcap.writer import CompressionType, IndexType, Writer

from ramp import __version__
from ramp.recorder.schemas import MESSAGE_ENCODING, SCHEMA_ENCODING, ChannelSpec

log = logging.getLogger("ramp.recorder")

#: A queued record: (topic, supervisor time in s, JSON payload).
Record = tuple[str, float, bytes]
#: Opens a new file for writing; tests pass one that is slow or fails.
Opener = Callable[[Path], IO[bytes]]

FILE_RE = re.compile(r"^ramp-(\d{6,})-[0-9TZ]+\.mcap$")
SLICE_RECORDS = 16       # records framed between two pauses: ~75 us of CPU, 0.9 ms at most
                         # when a chunk is closed in the slice (measured, 2 cores)
SLICE_PAUSE_S = 0.0002   # a real sleep, so a tick waiting for the interpreter lock gets it
POLL_S = 0.05            # how often the thread looks at the queue when it is idle
RETRY_S = 5.0            # after a write error, how long until a new file is tried
SCAN_SLICE = 256         # directory entries looked at between two pauses (the first scan)
PRUNE_SLICE = 16         # old files deleted between two pauses
PRUNE_IN_DRAIN = 2       # ... and between two slices of records, when there is a backlog
WARN_AGAIN_S = 60.0      # a write failure after this long without one warns again
CHUNK_BYTES = 32 << 10   # a chunk is closed at this size (before compression), or on time
RECORD_OVERHEAD = 47     # bytes of MCAP framing and message index per message (uncompressed)
#: Every index, message indexes included: Foxglove's reader (@mcap/core) refuses a chunk
#: index without them. mcap-python writes them in one Python loop per chunk, which is why
#: chunks stay small (CHUNK_BYTES).
INDEXES = IndexType.ALL
COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
               "none": CompressionType.NONE}


def default_opener(path: Path) -> IO[bytes]:
    # "x": never overwrite a file we did not make.
    return open(path, "xb")  # noqa: SIM115 - closed by the segment writer


class TimeBase:
    """The supervisor's clock (seconds) to MCAP log times (ns since the Unix epoch).

    `log_time_ns = origin_ns + round((t - t0) * 1e9)`, where `t0` is the supervisor's clock
    when the recorder started and `origin_ns` the wall clock (UTC) read once at that moment.
    Time in the file therefore runs exactly as the supervisor's clock (never stepped by NTP),
    and Foxglove shows it as a real date. Both numbers are written in each file's `ramp`
    metadata record, so a reader can map log times back to supervisor time.
    """

    def __init__(self, t0: float, origin_ns: int) -> None:
        self.t0 = t0
        self.origin_ns = origin_ns

    def ns(self, t: float) -> int:
        return max(0, self.origin_ns + round((t - self.t0) * 1e9))

    def seconds(self, log_time_ns: int) -> float:
        """The supervisor's clock at a log time."""
        return self.t0 + (log_time_ns - self.origin_ns) / 1e9


def recording_files(directory: Path) -> list[tuple[int, Path]]:
    """The recorder's own files in `directory`, oldest first, as (index, path)."""
    return [(i, directory / name) for i, name in recording_names(directory)]


def recording_names(directory: Path, pause: Callable[[], None] | None = None
                    ) -> list[tuple[int, str]]:
    """The recorder's own files in `directory`, oldest first, as (index, file name);
    `pause` is called every SCAN_SLICE entries (the writer thread sleeps there, so a tick
    waiting for the interpreter lock gets it)."""
    found: dict[int, str] = {}
    with contextlib.suppress(FileNotFoundError, NotADirectoryError), os.scandir(directory) as it:
        for n, entry in enumerate(it, 1):
            m = FILE_RE.match(entry.name)
            if m:
                found[int(m.group(1))] = entry.name
            if pause is not None and n % SCAN_SLICE == 0:
                pause()
    return [(i, found[i]) for i in sorted(found)]


def _pause() -> None:
    time.sleep(SLICE_PAUSE_S)


class SegmentWriter:
    """The current MCAP file: opened, written, rotated at `max_bytes`, old ones deleted.

    Files are named `ramp-NNNNNN-YYYYMMDDTHHMMSSZ.mcap`: the index continues from the
    highest already in the directory, so the order of files does not depend on the wall
    clock (an SBC without a real-time clock boots in the past). The date is only a label.
    """

    def __init__(self, directory: Path, max_bytes: int, keep: int, timebase: TimeBase,
                 channels: Mapping[str, ChannelSpec], *, opener: Opener = default_opener,
                 compression: str = "zstd", session: Mapping[str, str] | None = None) -> None:
        self.directory = directory
        self.max_bytes = max_bytes
        self.keep = keep
        self.timebase = timebase
        self.channels = channels  # shared with the tick side: read, never written, here
        self.opener = opener
        self.compression = COMPRESSION[compression]
        self.session = dict(session or {})
        self.path: Path | None = None
        self.files_opened = 0
        self.written = 0
        #: Records written into a file that was deleted or replaced before they were safe.
        self.lost = 0
        self._ours: deque[tuple[int, str]] | None = None  # our files' names, oldest first
        self._next_index = 1
        self._identity: tuple[int, int] | None = None  # (st_dev, st_ino) of the open file
        self._checked_written = 0
        self._pruned: tuple[int, str, str] = (0, "", "")  # (count, first, last) not yet logged
        self._file: IO[bytes] | None = None
        self._mcap: Writer | None = None
        self._ids: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._unflushed = 0
        self._unflushed_bytes = 0
        self._unsynced = False
        #: Bytes (before compression) after which a chunk is closed early: small chunks keep
        #: each chunk's framing and compression short (the interpreter lock), and a file ends
        #: within an eighth of `max_bytes` (plus its index) past it.
        self.chunk_bytes = max(1024, min(CHUNK_BYTES, max_bytes // 8))

    @property
    def is_open(self) -> bool:
        return self._mcap is not None

    def open_next(self) -> Path:
        """Start a new file (raises OSError); the oldest beyond `keep` are left to `prune`.

        The directory is scanned for earlier files once, at the first open; from then on the
        recorder keeps its own list."""
        self.directory.mkdir(parents=True, exist_ok=True)
        if self._ours is None:
            existing = recording_names(self.directory, _pause)
            self._ours = deque(existing)
            self._next_index = existing[-1][0] + 1 if existing else 1
        stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")  # a label only
        for _ in range(100):  # a file of that name made by someone else: take the next index
            index = self._next_index
            self._next_index += 1
            path = self.directory / f"ramp-{index:06d}-{stamp}.mcap"
            try:
                f = self.opener(path)
                break
            except FileExistsError:
                continue
        else:
            raise FileExistsError(f"100 file names after ramp-{index - 99:06d} are taken")
        if isinstance(f, io.RawIOBase):  # buffer it here, so closing it flushes what mcap wrote
            f = io.BufferedWriter(f)
        try:
            mcap = Writer(f, compression=self.compression, chunk_size=4 << 20,
                          index_types=INDEXES)
            mcap.start(profile="", library=f"ramp {__version__} (mcap-python)")
            mcap.add_metadata("ramp", {
                **self.session,
                "clock_t0_s": repr(self.timebase.t0),
                "clock_origin_ns": str(self.timebase.origin_ns),
                "time_mapping": "log_time_ns = clock_origin_ns + round((t - clock_t0_s) * 1e9)",
                "file_index": str(index),
            })
            self._file, self._mcap, self.path = f, mcap, path
            self._identity = _identity(f)
            self._checked_written = self.written
            self._ids = {}
            for topic in list(self.channels):  # every known channel, even before its data
                self._channel_id(topic)
            mcap.flush()
        except BaseException:
            self._file, self._mcap = None, None
            with contextlib.suppress(OSError):
                f.close()
            with contextlib.suppress(OSError):
                path.unlink()  # a full disk must not fill the directory with empty files
            raise
        self.files_opened += 1
        self._ours.append((index, path.name))
        return path

    def announce(self) -> None:
        """Log where the recording goes (once, when its first file is open)."""
        log.info("recorder: writing %s (new file every %g MB, keeping %d)", self.path,
                 self.max_bytes / 1e6, self.keep)

    @property
    def to_prune(self) -> int:
        """Old files beyond `keep` still to delete."""
        return max(0, len(self._ours) - self.keep) if self._ours is not None else 0

    def prune(self, most: int = PRUNE_SLICE) -> int:
        """Delete up to `most` of the oldest files beyond `keep`; returns how many were
        looked at. One log line when the backlog is cleared, however long it was."""
        ours = self._ours
        done = 0
        while ours is not None and len(ours) > self.keep and done < most:
            index, name = ours.popleft()
            done += 1
            if self.path is not None and name == self.path.name:
                ours.appendleft((index, name))  # never the file being written
                break
            old = self.directory / name
            try:
                old.unlink()
                n, first, _ = self._pruned
                self._pruned = (n + 1, first or name, name)
            except FileNotFoundError:
                pass  # someone else removed it
            except OSError as exc:
                log.warning("recorder: cannot remove %s: %s", old, exc.strerror or exc)
        n, first, last = self._pruned
        if n and self.to_prune == 0:
            which = first if n == 1 else f"{n} files ({first} to {last})"
            log.info("recorder: removed %s, keeping the newest %d", which, self.keep)
            self._pruned = (0, "", "")
        return done

    def still_ours(self) -> bool:
        """False when the open file's path is gone (deleted, or renamed away) or names
        another inode (replaced, even by a directory); the records written into it since
        the last check are then counted in `lost`."""
        f, path, identity = self._file, self.path, self._identity
        if f is None or path is None or identity is None:
            return True
        gone = ""
        try:
            st = os.stat(path)
            if (st.st_dev, st.st_ino) != identity:
                gone = "replaced"
        except FileNotFoundError:
            gone = "deleted"
        except (OSError, ValueError, AttributeError):
            return True  # not a real file (tests' openers), or cannot tell: keep writing
        if not gone:
            self._checked_written = self.written
            return True
        lost = self.written - self._checked_written
        self.lost += lost
        log.warning("recorder: %s was %s while being written; %d records in it are lost; "
                    "starting a new file", path, gone, lost)
        self.abandon()
        return False

    def _channel_id(self, topic: str) -> int:
        cid = self._ids.get(topic)
        if cid is None:
            assert self._mcap is not None
            spec = self.channels[topic]
            sid = self._mcap.register_schema(spec.schema_name, SCHEMA_ENCODING,
                                             spec.schema_bytes())
            cid = self._mcap.register_channel(topic, MESSAGE_ENCODING, sid,
                                              dict(spec.metadata))
            self._ids[topic] = cid
        return cid

    def write(self, topic: str, t: float, payload: bytes) -> None:
        assert self._mcap is not None
        cid = self._ids.get(topic)
        if cid is None:
            cid = self._channel_id(topic)
        seq = self._sequence.get(topic, 0) + 1
        self._sequence[topic] = seq
        ns = self.timebase.ns(t)
        self._mcap.add_message(cid, ns, payload, ns, seq & 0xFFFFFFFF)
        self.written += 1
        self._unflushed += 1
        self._unflushed_bytes += len(payload) + RECORD_OVERHEAD
        if self._unflushed_bytes >= self.chunk_bytes:
            self.flush(sync=False)

    def flush(self, sync: bool = True) -> None:
        """Close the chunk in progress (written: a crash keeps it) and, with `sync`, make
        what was written durable (a power loss keeps it); rotate when the file is full.

        The writer thread syncs on its time-based flush only: an SD card can take tens of
        milliseconds per `fdatasync`, too slow to pay for every chunk."""
        if self._mcap is None or self._file is None:
            return
        if self._unflushed:
            self._mcap.flush()
            self._unflushed = self._unflushed_bytes = 0
            self._unsynced = True
        if sync and self._unsynced:
            _sync(self._file)
            self._unsynced = False
        if self._file.tell() >= self.max_bytes:
            # The next record opens the next file (the writer thread's drain does), so a run
            # that ends right after a rotation leaves no empty file behind.
            self.finish()

    def finish(self, extra: Mapping[str, str] | None = None) -> None:
        """Write the summary and footer (the file is then indexed) and close it."""
        if self._mcap is None or self._file is None:
            return
        mcap, f = self._mcap, self._file
        self._mcap, self._file = None, None
        try:
            if extra:
                mcap.add_metadata("ramp.recorder", dict(extra))
            mcap.finish()
            f.flush()
            _sync(f)
        finally:
            f.close()

    def abandon(self) -> None:
        """After a write error: close the file without its footer (it stays readable)."""
        f = self._file
        self._mcap, self._file, self._identity = None, None, None
        if f is not None:
            with contextlib.suppress(OSError, ValueError):
                f.close()


def _identity(f: IO[bytes]) -> tuple[int, int] | None:
    try:
        st = os.fstat(f.fileno())
    except (AttributeError, OSError, ValueError):
        return None  # not a real file (tests)
    return st.st_dev, st.st_ino


def _sync(f: IO[bytes]) -> None:
    """Push the file to the disk, so a power loss keeps it (not only a crash)."""
    try:
        fd = f.fileno()
    except (AttributeError, OSError, ValueError):
        return  # not a real file (tests): nothing to sync
    f.flush()
    os.fdatasync(fd)


class WriterThread(threading.Thread):
    """Drains the recorder's queue into a `SegmentWriter` until stopped."""

    def __init__(self, queue: deque[Record], segments: SegmentWriter, *,
                 flush_s: float = 0.5, retry_s: float = RETRY_S,
                 final_metadata: Callable[[], Mapping[str, str]] | None = None) -> None:
        super().__init__(name="ramp-recorder", daemon=True)
        self.queue = queue
        self.segments = segments
        self.flush_s = flush_s
        self.retry_s = retry_s
        self.final_metadata = final_metadata
        self.bytes_out = 0     # payload bytes taken off the queue (the tick side counts in)
        self.dropped_io = 0    # records lost to write errors (and a deleted file's, below)
        self.failed_at: float | None = None  # the failure the current retry waits after
        self._last_failure: float | None = None
        self._stop_event = threading.Event()
        self._last_flush = 0.0

    def stop(self) -> None:
        self._stop_event.set()

    @property
    def lost(self) -> int:
        """Every record taken off the queue and not safely in a file."""
        return self.dropped_io + self.segments.lost

    def run(self) -> None:
        self._last_flush = time.monotonic()
        if not self.segments.is_open:
            self._reopen()  # the recorder left the first file to this thread
        while True:
            stopping = self._stop_event.is_set()
            pruning = False
            try:
                self._drain()
                if stopping or time.monotonic() - self._last_flush >= self.flush_s:
                    self._flush()
                pruning = self.segments.to_prune > 0
                if pruning:
                    self.segments.prune()  # a few at a time, between drains
                    time.sleep(SLICE_PAUSE_S)
            except Exception as exc:  # noqa: BLE001 - a bug here must not end the recording
                log.exception("recorder: unexpected error in the writer; going on")
                self._failed(exc)
            if stopping and not self.queue and not pruning:
                break
            if not stopping and not pruning:
                self._stop_event.wait(POLL_S)
        final = dict(self.final_metadata()) if self.final_metadata else {}
        self._guarded(lambda: self.segments.finish(final))

    def _flush(self) -> None:
        self._guarded(self.segments.flush)
        self._last_flush = time.monotonic()
        self._guarded(self.segments.still_ours)

    def _drain(self) -> None:
        """Everything queued, in slices; a chunk is closed on time even under a flood."""
        q = self.queue
        seg = self.segments
        n = 0
        while q:
            topic, t, payload = q.popleft()
            self.bytes_out += len(payload)
            if not seg.is_open and not self._reopen():
                self.dropped_io += 1
                continue
            try:
                seg.write(topic, t, payload)
            except Exception as exc:  # noqa: BLE001 - counted and retried, whatever it is
                self.dropped_io += 1
                self._failed(exc)
                continue
            n += 1
            if n % SLICE_RECORDS == 0:
                if time.monotonic() - self._last_flush >= self.flush_s:
                    self._flush()
                if seg.to_prune:  # under a flood the queue never empties: prune as we go
                    seg.prune(PRUNE_IN_DRAIN)
                time.sleep(SLICE_PAUSE_S)

    def _reopen(self) -> bool:
        if self.failed_at is not None and time.monotonic() - self.failed_at < self.retry_s:
            return False
        try:
            path = self.segments.open_next()
        except Exception as exc:  # noqa: BLE001 - a NUL in a path is a ValueError, say
            self._failed(exc)
            return False
        if self.failed_at is not None:
            log.info("recorder: writing again, to %s", path)
        elif self.segments.files_opened == 1:
            self.segments.announce()
        self.failed_at = None
        return True

    def _guarded(self, action: Callable[[], Any]) -> None:
        try:
            action()
        except Exception as exc:  # noqa: BLE001 - counted and retried, whatever it is
            self._failed(exc)

    def _failed(self, exc: Exception) -> None:
        now = time.monotonic()
        # One warning per episode: a failure within WARN_AGAIN_S of the last one belongs to
        # it, even when a new file opened in between (a disk still full takes the header).
        first = self._last_failure is None or now - self._last_failure >= WARN_AGAIN_S
        self.failed_at = self._last_failure = now
        path = self.segments.path
        self.segments.abandon()
        if first:
            why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            log.warning("recorder: cannot write %s: %s; records are dropped until it can "
                        "(retrying every %g s)", path or self.segments.directory, why,
                        self.retry_s)
