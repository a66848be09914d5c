"""Reading recordings back: every message in file order, even from a file cut short.

A file the supervisor closed has its index and footer; one cut by a crash or a power loss
ends after its last whole chunk (or in the middle of one). Both are read the same way, record
by record from the start with the `mcap` stream reader, CRCs checked, stopping at the first
record that is missing or damaged; `truncated` says which files ended early and why. The
reading shows a progress bar for large files (tqdm, from the `log` extra).

A file is input from anywhere (a team mails one around), so nothing in it is trusted: only
regular, non-empty files are read (a directory, a FIFO or `/dev/zero` is named as such, never
waited on); one record may be at most `MAX_RECORD_BYTES`, and a chunk may expand to at most
`MAX_CHUNK_BYTES` (checked on what it declares, and again while decompressing, so a 2 KB
"zip bomb" cannot take a gigabyte); each JSON payload is parsed without NaN or infinities,
nesting is bounded, and the fields the summary and the plot read are checked for their type.
Anything else is a `BadRecording` whose text names the file and what is wrong with it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, NamedTuple

from mcap.exceptions import InvalidMagic, RecordLengthLimitExceeded
from mcap.records import Channel, Chunk, McapRecord, Message, Metadata
from mcap.stream_reader import StreamReader, breakup_chunk

from ramp.common.files import NotRegularFile, open_regular
from ramp.recorder.schemas import (
    TOPIC_COMMANDS,
    TOPIC_EVENTS,
    TOPIC_LOG,
    TOPIC_MCP_IN,
    TOPIC_MCP_OUT,
    TOPIC_MODULE_STATE,
)

#: Files at least this big show a progress bar (when stderr is a terminal).
PROGRESS_MIN_BYTES = 8_000_000
#: The most one chunk may expand to. The recorder closes chunks at 32 KiB and mcap-python's
#: default is 1 MiB; anything near this is not a recording of ours.
MAX_CHUNK_BYTES = 64 << 20
#: The most one record may take in the file.
MAX_RECORD_BYTES = 64 << 20
#: The deepest nesting a payload may have (ours nest 3 levels; Foxglove's a few more).
MAX_JSON_DEPTH = 32


class Msg(NamedTuple):
    """One recorded message: its topic, log time (ns since the epoch) and decoded JSON."""

    topic: str
    log_time: int
    data: Any


@dataclass
class FileInfo:
    path: Path
    size: int
    messages: int = 0
    complete: bool = False          # ended with its footer (closed by the recorder)
    truncated: str = ""             # why reading stopped early, if it did
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)


class BadRecording(ValueError):
    """A file `ramp log` cannot read as a recording; str() names the file and why."""


class NotMcap(BadRecording):
    """The file is not an MCAP file at all."""


class _Counting:
    """A file wrapper that reports bytes read to a progress bar."""

    def __init__(self, f: IO[bytes], bar: Any) -> None:
        self.f = f
        self.bar = bar

    def read(self, n: int = -1) -> bytes:
        data = self.f.read(n)
        if self.bar is not None:
            self.bar.update(len(data))
        return data


def _progress_bar(total: int, show: bool | None) -> Any:
    if show is None:
        show = total >= PROGRESS_MIN_BYTES and sys.stderr.isatty()
    if not show:
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # the `log` extra is not installed: no bar
        return None
    return tqdm(total=total, unit="B", unit_scale=True, desc="reading", file=sys.stderr,
                leave=False)


class Recording:
    """The messages of one or more files (given oldest first), read once, in file order."""

    def __init__(self, paths: Sequence[str | Path], progress: bool | None = None) -> None:
        self.paths = [Path(p) for p in paths]
        self.progress = progress
        self.files: list[FileInfo] = []

    def __iter__(self) -> Iterator[Msg]:
        self.files = []
        opened = [_open(path) for path in self.paths]  # every file checked before reading
        try:
            bar = _progress_bar(sum(size for _, size in opened), self.progress)
            try:
                for path, (f, size) in zip(self.paths, opened, strict=True):
                    info = FileInfo(path, size)
                    self.files.append(info)
                    yield from self._read(path, f, info, bar)
            finally:
                if bar is not None:
                    bar.close()
        finally:
            for f, _ in opened:
                f.close()

    def _read(self, path: Path, raw: IO[bytes], info: FileInfo, bar: Any) -> Iterator[Msg]:
        channels: dict[int, Channel] = {}
        reader = StreamReader(_Counting(raw, bar), emit_chunks=True,  # type: ignore[arg-type]
                              validate_crcs=True, record_size_limit=MAX_RECORD_BYTES)
        records = reader.records
        while True:
            try:
                record = next(records)
            except StopIteration:
                info.complete = True
                return
            except InvalidMagic:
                if raw.tell() <= 8:
                    raise NotMcap(f"{path}: not an MCAP file") from None
                info.truncated = "the file ends without its closing magic bytes"
                return
            except RecordLengthLimitExceeded as exc:
                raise BadRecording(f"{path}: {exc} (a recording's records are at most "
                                   f"{MAX_RECORD_BYTES >> 20} MiB)") from None
            except Exception as exc:  # noqa: BLE001 - any damage ends the readable part
                info.truncated = _why(exc, raw.tell(), info.size)
                return
            inner = _unpack(path, record) if isinstance(record, Chunk) else [record]
            for r in inner:
                if isinstance(r, Message):
                    ch = channels.get(r.channel_id)
                    if ch is None or ch.message_encoding != "json":
                        continue
                    try:
                        data = decode_payload(ch.topic, r.data)
                    except ValueError as exc:
                        raise BadRecording(f"{path}: message {info.messages + 1} on "
                                           f"{_short(ch.topic)}: {exc}") from None
                    info.messages += 1
                    yield Msg(ch.topic, r.log_time, data)
                elif isinstance(r, Channel):
                    channels[r.id] = r
                elif isinstance(r, Metadata):
                    info.metadata[r.name] = dict(r.metadata)


def _open(path: Path) -> tuple[IO[bytes], int]:
    try:
        fd, size = open_regular(path)
    except NotRegularFile as exc:
        raise BadRecording(f"{path}: {exc.reason}") from None
    f = os.fdopen(fd, "rb")
    if size == 0:
        f.close()
        raise BadRecording(f"{path}: the file is empty (0 bytes); expected an MCAP recording")
    return f, size


# -- chunks ----------------------------------------------------------------------------------
def _unpack(path: Path, chunk: Chunk) -> list[McapRecord]:
    """A chunk's records, never expanding it past MAX_CHUNK_BYTES."""
    limit = MAX_CHUNK_BYTES
    if chunk.uncompressed_size > limit:
        raise BadRecording(f"{path}: a chunk declares {chunk.uncompressed_size:,} bytes once "
                           f"expanded, more than the {limit >> 20} MiB a recording's chunk may "
                           "(a zip bomb?)")
    data = _expand(path, chunk.compression, chunk.data, limit)
    if len(data) != chunk.uncompressed_size:
        raise BadRecording(f"{path}: a chunk expands to {'more than ' if len(data) > limit else ''}"
                           f"{min(len(data), limit):,} bytes, not the "
                           f"{chunk.uncompressed_size:,} it declares")
    try:
        return breakup_chunk(dataclasses.replace(chunk, compression="", data=data),
                             validate_crc=True)
    except Exception as exc:  # noqa: BLE001 - a damaged chunk, whatever mcap raises for it
        raise BadRecording(f"{path}: a damaged chunk: {type(exc).__name__} {exc}".strip()) \
            from None


def _expand(path: Path, compression: str, data: bytes, limit: int) -> bytes:
    """`data` decompressed, at most `limit` + 1 bytes of it (one more says "too big")."""
    if compression == "":
        return data
    try:
        if compression == "zstd":
            import zstandard

            out = bytearray()
            with zstandard.ZstdDecompressor().stream_reader(data) as reader:
                while len(out) <= limit:
                    piece = reader.read(min(1 << 20, limit + 1 - len(out)))
                    if not piece:
                        break
                    out += piece
            return bytes(out)
        if compression == "lz4":
            import lz4.frame

            result: bytes = lz4.frame.LZ4FrameDecompressor().decompress(
                data, max_length=limit + 1)
            return result
    except ImportError:
        raise BadRecording(f"{path}: chunks compressed with {compression}, and its "
                           "decompressor is not installed") from None
    except Exception as exc:  # noqa: BLE001 - the decompressors' own error types
        raise BadRecording(f"{path}: a chunk that does not decompress: {exc}") from None
    raise BadRecording(f"{path}: chunks compressed with {_short(compression)!r}, which RAMP "
                       "does not read (zstd, lz4 or none)")


# -- payloads ---------------------------------------------------------------------------------
def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_str(v: Any) -> bool:
    return isinstance(v, str)


def _is_object(v: Any) -> bool:
    return isinstance(v, dict)


#: The fields `ramp log summary` and `ramp log plot` read, per topic, and what each must be.
FIELDS: dict[str, dict[str, tuple[Callable[[Any], bool], str]]] = {
    TOPIC_MCP_IN: {"client": (_is_str, "text"), "line": (_is_str, "text")},
    TOPIC_MCP_OUT: {"client": (_is_str, "text"), "line": (_is_str, "text")},
    TOPIC_COMMANDS: {"bus": (_is_str, "text"), "channel": (_is_str, "text"),
                     "duty": (_is_number, "a number"), "kind": (_is_str, "text")},
    TOPIC_MODULE_STATE: {"module": (_is_str, "text"), "state": (_is_str, "text"),
                         "reason": (_is_str, "text")},
    TOPIC_EVENTS: {"kind": (_is_str, "text"), "text": (_is_str, "text")},
    TOPIC_LOG: {"level": (_is_int, "an integer"), "message": (_is_str, "text"),
                "name": (_is_str, "text"), "timestamp": (_is_object, "an object")},
}


class _NotANumber(ValueError):
    pass


def _no_constant(name: str) -> Any:
    raise _NotANumber(f"{name} is not a JSON number")


def decode_payload(topic: str, raw: bytes) -> Any:
    """One message's JSON, checked; ValueError says what is wrong with it."""
    try:
        data = json.loads(raw, parse_constant=_no_constant)
    except RecursionError:
        raise ValueError(f"nested deeper than {MAX_JSON_DEPTH} levels") from None
    except _NotANumber as exc:
        raise ValueError(str(exc)) from None
    except ValueError as exc:  # UnicodeDecodeError and JSONDecodeError among them
        raise ValueError(f"not JSON: {_short(str(exc))}") from None
    _check_tree(data)
    fields = FIELDS.get(topic)
    if (fields is not None or topic.endswith("/get")) and not isinstance(data, dict):
        raise ValueError(f"expected an object, got {_kind(data)}")
    for key, (ok, what) in (fields or {}).items():
        if key in data and not ok(data[key]):
            raise ValueError(f"{key!r} is {_kind(data[key])}, expected {what}")
    if topic.endswith("/get") and fields is None:
        for device, props in data.items():
            if not isinstance(props, dict):
                raise ValueError(f"{_short(device)!r} is {_kind(props)}, expected an object "
                                 "of properties")
    return data


def _check_tree(data: Any) -> None:
    """No number that is not finite (`1e999` parses as infinity), nesting bounded."""
    stack: list[tuple[Any, int]] = [(data, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{v} is not a finite number")
        if isinstance(v, dict | list):
            if depth > MAX_JSON_DEPTH:
                raise ValueError(f"nested deeper than {MAX_JSON_DEPTH} levels")
            items = v.values() if isinstance(v, dict) else v
            stack.extend((item, depth + 1) for item in items)


def _kind(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true/false"
    if isinstance(v, str):
        return f"the text {_short(v)!r}"
    if isinstance(v, int | float):
        return repr(v)
    return "a list" if isinstance(v, list) else "an object"


def _short(text: str, limit: int = 60) -> str:
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _why(exc: Exception, at: int, size: int) -> str:
    name = type(exc).__name__
    if name == "EndOfFile" or at >= size:
        return "the file ends in the middle of a record (cut by a crash or power loss)"
    return f"damaged record near byte {at}: {name} {exc}".strip()
