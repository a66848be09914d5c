"""Coverage-guided fuzzing of the MCP codec with atheris (issue 5, part 4).

Not a pytest module (its name does not start with `test_`): atheris is an optional tool, not
a project dependency. Install it into the venv and run, from the repository root:

    .venv/bin/pip install atheris
    .venv/bin/python tests/fuzz/atheris_mcp.py -runs=200000 [-max_len=8192] [corpus_dir]

Each input is cut into a `max_line`, chunk boundaries and a byte stream; the stream goes
through `LineSplitter` in those chunks and every message through `parse_message`. Checked
against the independent oracle in `tests/fuzz`: the split equals the SPEC's, every parse
agrees with the SPEC reading, limits hold, and nothing raises. A failure leaves a
`crash-...` file that reproduces it: `python tests/fuzz/atheris_mcp.py crash-...`.
"""

from __future__ import annotations

import sys
from pathlib import Path

import atheris

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

with atheris.instrument_imports(include=["ramp"]):
    from ramp.mcp.messages import clean_detail
    from ramp.mcp.protocol import (
        MAX_REQUESTS,
        LineSplitter,
        TooLong,
        format_responses,
        parse_message,
        parse_response_line,
    )

from tests.fuzz import reference_parse, reference_split  # noqa: E402


def check_message(msg: bytes) -> None:
    parsed = parse_message(msg)
    ref = reference_parse(msg)
    got = tuple((r.module, r.device, r.function, r.params) for r in parsed.requests)
    if got != ref.requests or (parsed.syntax_error is not None) != ref.syntax_error:
        raise AssertionError(f"parser and SPEC disagree on {msg!r}: {parsed} vs {ref}")
    if len(parsed.requests) > MAX_REQUESTS:
        raise AssertionError(f"{len(parsed.requests)} requests in one message")
    if parsed.syntax_error is not None:
        line = format_responses([parsed.syntax_error])
        detail = str(parsed.syntax_error.values[1])
        if clean_detail(detail) != detail or parse_response_line(line) != [parsed.syntax_error]:
            raise AssertionError(f"bad syntax error line {line!r}")


def fuzz_one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    max_line = fdp.ConsumeIntInRange(1, 300)
    cuts = sorted(fdp.ConsumeIntInRange(0, 4096) for _ in range(fdp.ConsumeIntInRange(0, 8)))
    stream = fdp.ConsumeBytes(fdp.remaining_bytes())
    splitter = LineSplitter(max_line)
    got: list[bytes | TooLong] = []
    prev = 0
    for cut in [*cuts, len(stream)]:
        cut = min(max(cut, prev), len(stream))
        got.extend(splitter.feed(stream[prev:cut]))
        prev = cut
        if splitter.pending > max_line + 1:
            raise AssertionError(f"splitter holds {splitter.pending} bytes, limit {max_line}")
    want = reference_split(stream, max_line)
    if len(got) != len(want):
        raise AssertionError(f"{len(got)} messages, SPEC says {len(want)}: {stream!r}")
    for g, w in zip(got, want, strict=True):
        if w is None:
            if not isinstance(g, TooLong):
                raise AssertionError(f"an over-long message came through: {g!r}")
            continue
        if g != w:
            raise AssertionError(f"message {g!r}, SPEC says {w!r}")
        check_message(w)
    check_message(stream.replace(b"\n", b""))  # and the whole input as one message


def main() -> None:
    atheris.Setup(sys.argv, fuzz_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
