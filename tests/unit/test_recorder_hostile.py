"""`ramp log` on files from anywhere (issue 19 item 9): every bad file is one clear line and
exit 2, at once; `ramp log plot -o NAME` says the file it really wrote.

Before: a 2 KB file whose chunk expands to 1 GiB hung and took a gigabyte; deeply nested
JSON ended in RecursionError, NaN and a string where a number belongs in ValueError
tracebacks; a directory, a FIFO or /dev/zero was "no such file" (and /dev/zero, read through
the progress bar's stat, was not even reached); an empty file blamed "a crash or power loss";
`-o out` wrote `out.png` and said `wrote out`."""

from __future__ import annotations

import os
import resource
import struct
import time
from pathlib import Path

import pytest
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import Chunk, DataEnd, Footer, Header
from mcap.writer import CompressionType, Writer

from ramp.recorder.logcli import main
from ramp.recorder.reading import MAX_CHUNK_BYTES

MAGIC = b"\x89MCAP0\r\n"


def crafted(path: Path, chunk: Chunk) -> Path:
    """A file of a header, one chunk, data end and footer: nothing else to read."""
    b = RecordBuilder()
    Header(profile="", library="hostile").write(b)
    chunk.write(b)
    DataEnd(0).write(b)
    Footer(0, 0, 0).write(b)
    path.write_bytes(MAGIC + b.end() + MAGIC)
    return path


def zeros_zstd(n: int) -> bytes:
    """`n` zero bytes, zstd-compressed in one frame, without holding them in memory."""
    c = zstandard.ZstdCompressor(level=1).compressobj()
    block = bytes(1 << 20)
    out = [c.compress(block) for _ in range(n >> 20)]
    return b"".join(out) + c.flush()


def with_payloads(path: Path, topic: str, *payloads: bytes) -> Path:
    """A valid MCAP file (mcap-python's writer) holding raw JSON payloads on `topic`."""
    with path.open("wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel(topic, "json", sid)
        for i, p in enumerate(payloads):
            w.add_message(cid, i, p, i)
        w.finish()
    return path


def summary(path: Path | str, capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    code = main(["summary", "--no-progress", str(path)])
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    return code, out.err.splitlines()


GIB = 1 << 30


@pytest.mark.timeout(60)
@pytest.mark.parametrize("declared", [GIB, 1 << 15])
def test_a_zip_bomb_chunk_is_refused_without_expanding_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], declared: int) -> None:
    """The same 1 GiB of zeros in a ~40 KB file, declared honestly, or declared as 32 KiB."""
    data = zeros_zstd(GIB)
    f = crafted(tmp_path / "bomb.mcap", Chunk(message_start_time=0, message_end_time=0,
                                              uncompressed_size=declared, uncompressed_crc=0,
                                              compression="zstd", data=data))
    assert f.stat().st_size < 100_000
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.monotonic()
    code, lines = summary(f, capsys)
    took = time.monotonic() - t0
    grown_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss_before
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"ramp log: {f}: a chunk ")
    assert ("declares 1,073,741,824 bytes" if declared == GIB else
            "expands to more than 67,108,864 bytes, not the 32,768") in lines[0]
    assert took < 5.0
    assert grown_kb * 1024 < 4 * MAX_CHUNK_BYTES


BAD_PAYLOADS = {
    "deeply nested JSON": ("/robot/get", b"[" * 100_000 + b"]" * 100_000,
                           "message 1 on /robot/get: nested deeper than 32 levels"),
    "nesting just past the limit": ("/x", b'{"a":' * 40 + b"1" + b"}" * 40,
                                    "message 1 on /x: nested deeper than 32 levels"),
    "NaN": ("/robot/commands", b'{"bus": "b", "channel": "m.d", "duty": NaN}',
            "message 1 on /robot/commands: NaN is not a JSON number"),
    "an overflowing number": ("/base/get", b'{"battery": {"volt": 1e999}}',
                              "message 1 on /base/get: inf is not a finite number"),
    "a string where a number belongs": (
        "/robot/commands", b'{"bus": "b", "channel": "m.d", "duty": "fast"}',
        "message 1 on /robot/commands: 'duty' is the text 'fast', expected a number"),
    "a string log level": ("/log", b'{"level": "x", "message": "m"}',
                           "message 1 on /log: 'level' is the text 'x', expected an integer"),
    "a list where rows belong": ("/robot/get", b"[1, 2]",
                                 "message 1 on /robot/get: expected an object, got a list"),
    "a device that is not an object": ("/base/get", b'{"battery": 5}',
                                       "'battery' is 5, expected an object of properties"),
    "not JSON": ("/robot/events", b"\xff\xfe", "message 1 on /robot/events: not JSON"),
}


@pytest.mark.parametrize("case", sorted(BAD_PAYLOADS))
def test_a_bad_payload_is_one_line_naming_the_message(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str) -> None:
    topic, payload, expected = BAD_PAYLOADS[case]
    f = with_payloads(tmp_path / "bad.mcap", topic, payload)
    code, lines = summary(f, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"ramp log: {f}: ") and expected in lines[0], lines


def test_good_payloads_still_read(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = with_payloads(tmp_path / "ok.mcap", "/robot/commands",
                      b'{"bus": "b", "channel": "m.d", "duty": 0.5, "kind": "motor"}')
    assert main(["summary", "--no-progress", str(f)]) == 0
    assert "messages" in capsys.readouterr().out


@pytest.mark.timeout(20)
@pytest.mark.parametrize("what", ["a directory", "a FIFO", "/dev/zero", "an empty file",
                                  "a missing file", "a text file"])
def test_files_that_are_not_recordings_are_named_for_what_they_are(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], what: str) -> None:
    f = tmp_path / "x.mcap"
    expected = {"a directory": "cannot read: it is a directory; expected a regular file",
                "a FIFO": "cannot read: it is a FIFO (pipe); expected a regular file",
                "/dev/zero": "cannot read: it is a character device; expected a regular file",
                "an empty file": "the file is empty (0 bytes); expected an MCAP recording",
                "a missing file": "cannot read: no such file",
                "a text file": "not an MCAP file"}[what]
    if what == "a directory":
        f.mkdir()
    elif what == "a FIFO":
        os.mkfifo(f)
    elif what == "/dev/zero":
        f = Path("/dev/zero")
    elif what == "an empty file":
        f.touch()
    elif what == "a text file":
        f.write_text("hello\n" * 10)
    t0 = time.monotonic()
    code, lines = summary(f, capsys)
    assert time.monotonic() - t0 < 5
    assert code == 2 and lines == [f"ramp log: {f}: {expected}"]


def test_plot_says_the_file_it_really_wrote(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    payload = b'{"battery": {"volt": 24.5}}'
    f = with_payloads(tmp_path / "ok.mcap", "/base/get", payload, payload)
    out = tmp_path / "plots"
    out.mkdir()
    assert main(["plot", "--no-progress", str(f), "-o", str(out)]) == 0
    said = capsys.readouterr().out.strip()
    written = tmp_path / "plots.png"
    assert said == f"ramp log: wrote {written}" and written.is_file()  # before: "wrote .../plots"
    assert main(["plot", "--no-progress", str(f), "-o", str(tmp_path / "p.svg")]) == 0
    assert capsys.readouterr().out.strip().endswith("p.svg")


def test_the_crafted_file_helper_makes_a_readable_file(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """The bomb test's file is an MCAP file apart from its chunk (so the test can fail)."""
    payload = b""
    f = crafted(tmp_path / "ok.mcap", Chunk(message_start_time=0, message_end_time=0,
                                            uncompressed_size=len(payload),
                                            uncompressed_crc=0, compression="", data=payload))
    assert main(["summary", "--no-progress", str(f)]) == 0
    assert struct.unpack("<Q", MAGIC) and "complete" in capsys.readouterr().out
