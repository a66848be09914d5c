"""Reading recordings back: every message in file order, even from a file cut short.

A file the supervisor closed has its index and footer; one cut by a crash or a power loss
ends after its last whole chunk (or in the middle of one). Both are read the same way, record
by record from the start with the `mcap` stream reader, CRCs checked, stopping at the first
record that is missing or damaged; `truncated` says which files ended early and why. The
reading shows a progress bar for large files (tqdm, from the `log` extra).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, NamedTuple

from mcap.exceptions import InvalidMagic
from mcap.records import Channel, Message, Metadata
from mcap.stream_reader import StreamReader

#: Files at least this big show a progress bar (when stderr is a terminal).
PROGRESS_MIN_BYTES = 8_000_000


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


class NotMcap(ValueError):
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
        total = sum(p.stat().st_size for p in self.paths)
        bar = _progress_bar(total, self.progress)
        try:
            for path in self.paths:
                info = FileInfo(path, path.stat().st_size)
                self.files.append(info)
                yield from self._read(path, info, bar)
        finally:
            if bar is not None:
                bar.close()

    def _read(self, path: Path, info: FileInfo, bar: Any) -> Iterator[Msg]:
        channels: dict[int, Channel] = {}
        with open(path, "rb") as raw:
            reader = StreamReader(_Counting(raw, bar), validate_crcs=True)  # type: ignore[arg-type]
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
                except Exception as exc:  # noqa: BLE001 - any damage ends the readable part
                    info.truncated = _why(exc, raw.tell(), info.size)
                    return
                if isinstance(record, Message):
                    ch = channels.get(record.channel_id)
                    if ch is None:
                        continue
                    try:
                        data = json.loads(record.data)
                    except ValueError:
                        continue
                    info.messages += 1
                    yield Msg(ch.topic, record.log_time, data)
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Metadata):
                    info.metadata[record.name] = dict(record.metadata)


def _why(exc: Exception, at: int, size: int) -> str:
    name = type(exc).__name__
    if name == "EndOfFile" or at >= size:
        return "the file ends in the middle of a record (cut by a crash or power loss)"
    return f"damaged record near byte {at}: {name} {exc}".strip()
