"""MCP codec: byte-string tests for every grammar rule, plus hypothesis properties."""

from __future__ import annotations

import re
import tracemalloc

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ramp.errors import ProtocolError
from ramp.mcp.messages import Request, Response
from ramp.mcp.protocol import (
    LineSplitter,
    ParsedMessage,
    TooLong,
    _scan_request,
    _skip_blanks,
    format_request,
    format_requests,
    format_response,
    format_responses,
    format_value,
    parse_message,
    parse_response_line,
    syntax_error,
    too_long_response,
)

GET = Request("base", "base", "get")


def detail(p: ParsedMessage) -> str:
    assert p.syntax_error is not None
    assert p.syntax_error.module == "robot"
    assert p.syntax_error.device == "mcp"
    assert p.syntax_error.prop == "error"
    assert p.syntax_error.values[0] == "syntax"
    d = p.syntax_error.values[1]
    assert isinstance(d, str)
    return d


def assert_clean(d: str) -> None:
    assert not set(d) & set(",()\r\n"), d
    assert all(32 <= ord(c) < 127 for c in d), d


# --------------------------------------------------------------------------- parse_message


def test_single_request() -> None:
    p = parse_message(b"base:lf_wheel.vel=(50)")
    assert p == ParsedMessage((Request("base", "lf_wheel", "vel", ("50",)),), None)
    assert not p.heartbeat


def test_requests_are_concatenated() -> None:
    p = parse_message(b"base:base.get=()ble:ble.get=()robot:watchdog.timeout=(0.5)")
    assert p.requests == (
        GET,
        Request("ble", "ble", "get"),
        Request("robot", "watchdog", "timeout", ("0.5",)),
    )
    assert p.syntax_error is None


@pytest.mark.parametrize("line", [b"", b" ", b"\t \t", b"\r", b"  \r"])
def test_empty_message_is_heartbeat(line: bytes) -> None:
    p = parse_message(line)
    assert p.heartbeat
    assert p.requests == () and p.syntax_error is None


def test_whitespace_between_requests_and_around_params() -> None:
    p = parse_message(b" \tbase:base.drive=( 50 ,\t-12.5 )  base:base.get=(  )\t ")
    assert p.syntax_error is None
    assert p.requests == (Request("base", "base", "drive", ("50", "-12.5")), GET)


@pytest.mark.parametrize(
    ("line", "column"),
    [
        (b"base :base.get=()", 5),
        (b"base: base.get=()", 6),
        (b"base:base .get=()", 10),
        (b"base:base. get=()", 11),
        (b"base:base.get =()", 14),
        (b"base:base.get= ()", 15),
        (b"base:lf_wheel.vel=(5 0)", 22),
    ],
)
def test_whitespace_elsewhere_is_a_syntax_error(line: bytes, column: int) -> None:
    p = parse_message(line)
    assert p.requests == ()
    d = detail(p)
    assert f"at column {column} " in d + " "
    assert_clean(d)


def test_params_stay_text() -> None:
    p = parse_message(b"a:b.c=(+5,-3.0e2,abc_1,.5,nan,1-2)")
    assert p.requests[0].params == ("+5", "-3.0e2", "abc_1", ".5", "nan", "1-2")


def test_crlf_and_lone_cr() -> None:
    assert parse_message(b"base:base.get=()\r").requests == (GET,)
    p = parse_message(b"base:base.get=()\rble:ble.get=()")
    assert p.requests == (GET,)
    assert "carriage return" in detail(p)


@pytest.mark.parametrize("params", [b"1,,2", b"1,", b",1", b",", b" , ", b"1, ,2"])
def test_empty_param_is_a_syntax_error(params: bytes) -> None:
    p = parse_message(b"base:base.get=()a:b.c=(" + params + b")")
    assert p.requests == (GET,)
    assert "empty parameter" in detail(p)


def test_error_mid_message_keeps_requests_before_it() -> None:
    p = parse_message(b"base:base.get=()ble:ble.get=()ble:lift;vel=(1)robot:robot.stop=()")
    assert p.requests == (GET, Request("ble", "ble", "get"))
    assert detail(p) == "expected '.' after device 'lift' at column 39 but found ';'"


def test_detail_names_what_was_expected_and_where() -> None:
    assert detail(parse_message(b"base.base.get=()")) == (
        "expected ':' after module 'base' at column 5 but found '.'"
    )
    assert detail(parse_message(b"base:base.get=(1")) == (
        "missing close parenthesis at end of message for 'base:base.get'"
    )
    assert detail(parse_message(b"base:base.get")) == (
        "expected '=' after function 'get' at column 14 but found end of message"
    )
    assert detail(parse_message(b"base:base.get=1")) == (
        "expected an open parenthesis after 'base:base.get=' at column 15 but found '1'"
    )
    assert detail(parse_message(b"base:base.get=()#")) == (
        "expected a module name at column 17 but found '#'"
    )
    assert detail(parse_message(b"base::x.y=()")) == (
        "expected a device name after ':' at column 6 but found ':'"
    )


@pytest.mark.parametrize(
    "line",
    [
        b"a:b.c=(1,,2)",
        b"a:b.c=((1)",
        b"a:b.c=(1)(",
        b"a:b.c=(1))",
        b"a:b.c=(x\ny)",
        b"a,b:c.d=()",
        b"a:b.c=(1 ,2 3)",
        b"a:b.c=(\xff)",
        b"\x00",
        b"a:b.c=(1;2)",
    ],
)
def test_detail_is_sanitized(line: bytes) -> None:
    d = detail(parse_message(line))
    assert d
    assert_clean(d)
    # The serialized error is a single well-formed response line with exactly two values.
    out = format_responses([syntax_error(d)])
    assert out.count(b"\n") == 1
    assert parse_response_line(out)[0].values[1] == d


def test_name_and_param_length_limits() -> None:
    n32, n33 = "m" * 32, "m" * 33
    p64, p65 = "9" * 64, "9" * 65
    ok = parse_message(f"{n32}:{n32}.{n32}=({p64},{p64})".encode())
    assert ok.syntax_error is None
    assert ok.requests[0] == Request(n32, n32, n32, (p64, p64))
    for line, word in (
        (f"{n33}:d.f=()", "module name longer than 32"),
        (f"m:{n33}.f=()", "device name longer than 32"),
        (f"m:d.{n33}=()", "function name longer than 32"),
        (f"m:d.f=(1,{p65})", "parameter longer than 64"),
    ):
        p = parse_message(line.encode())
        assert p.requests == ()
        assert word in detail(p)


def test_non_ascii_and_nul_do_not_raise() -> None:
    p = parse_message("base:base.get=()bäse:x.y=()".encode())
    assert p.requests == (GET,)
    assert "byte 0xc3" in detail(p)
    p = parse_message(b"base:base.get=()\x00")
    assert p.requests == (GET,)
    assert detail(p) == "expected a module name at column 17 but found byte 0x00"


def test_at_most_max_requests() -> None:
    exactly = parse_message(b"a:b.c=()" * 256 + b"  ")
    assert len(exactly.requests) == 256 and exactly.syntax_error is None
    over = parse_message(b"a:b.c=()" * 257)
    assert len(over.requests) == 256
    assert detail(over) == "too many requests in one message; at most 256"
    few = parse_message(b"a:b.c=(1)a:b.c=(2)a:b.c=(3)", max_requests=2)
    assert [r.params for r in few.requests] == [("1",), ("2",)]
    assert detail(few) == "too many requests in one message; at most 2"


def test_huge_message_is_bounded() -> None:
    p = parse_message(b"base:lf_wheel.vel=(50)" * 100_000)
    assert len(p.requests) == 256
    assert "too many requests" in detail(p)
    junk = parse_message(b"x" * 1_000_000)
    assert junk.requests == ()
    assert "module name longer than 32" in detail(junk)


def test_accepts_bytearray_and_memoryview() -> None:
    assert parse_message(bytearray(b"base:base.get=()")).requests == (GET,)
    assert parse_message(memoryview(b"base:base.get=()")).requests == (GET,)


# --------------------------------------------------------------------------- formatting


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (True, "1"),
        (False, "0"),
        (0, "0"),
        (-42, "-42"),
        (10**20, "100000000000000000000"),
        (18.5, "18.5"),
        (0.0, "0.0"),
        (-0.0, "0.0"),
        (-0.0004, "0.0"),
        (3.0, "3.0"),
        (-3.14159, "-3.142"),
        (0.1 + 0.2, "0.3"),
        (2.25, "2.25"),
        (1e-4, "0.0"),
        (12.0006, "12.001"),
        (1e20, "100000000000000000000.0"),
        ("busy", "busy"),
        ("", ""),
    ],
)
def test_format_value(value: object, text: str) -> None:
    assert format_value(value) == text


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_format_value_rejects_non_finite(bad: float) -> None:
    with pytest.raises(ValueError):
        format_value(bad)


def test_format_value_rejects_other_types() -> None:
    with pytest.raises(TypeError):
        format_value(None)
    with pytest.raises(TypeError):
        format_value(b"1")


def test_format_value_numpy_scalars() -> None:
    np = pytest.importorskip("numpy")
    assert format_value(np.int64(-7)) == "-7"
    assert format_value(np.float64(24.1234)) == "24.123"
    assert format_value(np.float32(0.5)) == "0.5"


def test_format_responses_bytes() -> None:
    rs = [
        Response("base", "lf_wheel", "vel", (50,)),
        Response("base", "battery", "volt", (24.25,)),
        Response("base", "user_led", "on", (True,)),
        Response("robot", "tick", "late", (12, 40, 300)),
    ]
    assert format_response(rs[0]) == "base:lf_wheel.vel=(50)"
    assert format_responses(rs) == (
        b"base:lf_wheel.vel=(50)base:battery.volt=(24.25)base:user_led.on=(1)"
        b"robot:tick.late=(12,40,300)\n"
    )
    assert format_responses([]) == b"\n"
    assert format_responses([Response("robot", "robot", "modules")]) == b"robot:robot.modules=()\n"


def test_format_requests_bytes() -> None:
    rs = [GET, Request("base", "base", "drive", ("50", "-90"))]
    assert format_request(rs[1]) == "base:base.drive=(50,-90)"
    assert format_requests(rs) == b"base:base.get=()base:base.drive=(50,-90)\n"
    assert format_requests([]) == b"\n"


def test_too_long_response() -> None:
    assert format_responses([too_long_response(4096)]) == (
        b"robot:mcp.error=(too_long,message longer than 4096 bytes)\n"
    )
    assert too_long_response().values == ("too_long", "message longer than 4096 bytes")
    assert too_long_response(100).values[1] == "message longer than 100 bytes"


# --------------------------------------------------------------------------- responses


def test_parse_response_line_types_values() -> None:
    rs = parse_response_line(
        b"base:lf_wheel.vel=(-50)base:battery.volt=(24.5)robot:tick.late=(12,40,300)"
        b"robot:watchdog.state=(armed)robot:robot.modules=()x:y.z=(1e3,.5,+7,nan,1.2.3)\r\n"
    )
    assert rs == [
        Response("base", "lf_wheel", "vel", (-50,)),
        Response("base", "battery", "volt", (24.5,)),
        Response("robot", "tick", "late", (12, 40, 300)),
        Response("robot", "watchdog", "state", ("armed",)),
        Response("robot", "robot", "modules", ()),
        Response("x", "y", "z", (1000.0, 0.5, 7, "nan", "1.2.3")),
    ]
    assert type(rs[0].values[0]) is int and type(rs[1].values[0]) is float


def test_parse_response_line_error_detail() -> None:
    line = b"robot:mcp.error=(syntax,expected ':' after module 'base' at column 5; see docs)"
    (r,) = parse_response_line(line)
    assert r.values == ("syntax", "expected ':' after module 'base' at column 5; see docs")


def test_parse_response_line_empty_is_no_responses() -> None:
    assert parse_response_line(b"") == []
    assert parse_response_line(b"\r") == []
    assert parse_response_line(b"\n") == []


@pytest.mark.parametrize(
    "garbage",
    [b"hello", b"a:b.c=(1", b"a:b.c=(1)junk", b"a:b.c=(\xc3\xa4)", b"a:b.c=((1))", b":b.c=()"],
)
def test_parse_response_line_rejects_garbage(garbage: bytes) -> None:
    with pytest.raises(ProtocolError):
        parse_response_line(garbage)


# --------------------------------------------------------------------------- LineSplitter


def test_splitter_several_messages_in_one_feed() -> None:
    s = LineSplitter()
    assert s.feed(b"base:base.get=()\n\nble:ble.get=()\r\npart") == [
        b"base:base.get=()", b"", b"ble:ble.get=()",
    ]
    assert s.pending == 4
    assert s.feed(b"ial=()\n") == [b"partial=()"]
    assert s.pending == 0


def test_splitter_fragmented_byte_by_byte() -> None:
    s = LineSplitter()
    out: list[bytes | TooLong] = []
    for b in b"base:lf_wheel.vel=(50)\r\nbase:base.get=()\n":
        out += s.feed(bytes([b]))
    assert out == [b"base:lf_wheel.vel=(50)", b"base:base.get=()"]


def test_splitter_cr_split_from_lf() -> None:
    s = LineSplitter(max_line=4)
    assert s.feed(b"abcd\r") == []
    assert s.feed(b"\n") == [b"abcd"]
    assert s.feed(b"abcd") == []
    assert s.feed(b"\r\n") == [b"abcd"]


def test_splitter_too_long_limits() -> None:
    s = LineSplitter(max_line=8)
    assert s.feed(b"12345678\n") == [b"12345678"]
    assert s.feed(b"12345678\r\n") == [b"12345678"]
    assert s.feed(b"123456789\n") == [TooLong(9)]
    assert s.feed(b"1234567\r9\r\n") == [TooLong(10)]
    assert s.feed(b"ok\n") == [b"ok"]


def test_splitter_too_long_gives_one_marker_then_resyncs() -> None:
    s = LineSplitter(max_line=16)
    out: list[bytes | TooLong] = []
    out += s.feed(b"a:b.c=()\n" + b"x" * 10)
    out += s.feed(b"y" * 10)
    assert s.pending == 0  # discarding, not buffering
    out += s.feed(b"z" * 1000)
    out += s.feed(b"\r\na:b.c=(1)\n")
    assert out == [b"a:b.c=()", TooLong(1021), b"a:b.c=(1)"]
    assert s.pending == 0


def test_splitter_accepts_bytearray_and_memoryview() -> None:
    s = LineSplitter()
    out = s.feed(bytearray(b"ab\n")) + s.feed(memoryview(b"cd\n"))
    assert out == [b"ab", b"cd"]
    assert all(type(x) is bytes for x in out)


def test_splitter_memory_bounded_for_10mb_line() -> None:
    s = LineSplitter()
    chunk = b"A" * 65536
    tracemalloc.start()
    try:
        for _ in range(160):  # 10 MiB, no newline
            assert s.feed(chunk) == []
            assert s.pending <= 4097
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 64 * 1024, peak
    assert s.feed(b"\nbase:base.get=()\n") == [TooLong(160 * 65536), b"base:base.get=()"]


def test_splitter_single_huge_feed_is_not_buffered() -> None:
    s = LineSplitter()
    assert s.feed(b"B" * 10_000_000) == []
    assert s.pending == 0
    assert s.feed(b"\n") == [TooLong(10_000_000)]
    assert s.feed(b"C" * 5000 + b"\nok\n") == [TooLong(5000), b"ok"]


def test_splitter_reset() -> None:
    s = LineSplitter()
    s.feed(b"half")
    s.reset()
    assert s.pending == 0
    assert s.feed(b"x\n") == [b"x"]


# --------------------------------------------------------------------------- properties

NAME_CHARS = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_"
# Plain alphabets generate far faster than from_regex; the sizes reach both limits.
NAME = st.text(alphabet=NAME_CHARS, min_size=1, max_size=32)
PARAM = st.text(alphabet=NAME_CHARS + ".+-", min_size=1, max_size=64)
REQUEST = st.builds(Request, NAME, NAME, NAME, st.lists(PARAM, max_size=5).map(tuple))
BLANKS = st.text(alphabet=" \t", max_size=3)
PROPS = settings(max_examples=200, deadline=None)


@PROPS
@given(st.lists(REQUEST, max_size=12))
def test_format_then_parse_round_trips(requests: list[Request]) -> None:
    data = format_requests(requests)
    assert data.endswith(b"\n")
    assert parse_message(data[:-1]) == ParsedMessage(tuple(requests), None)


@PROPS
@given(st.lists(REQUEST, max_size=8), st.lists(BLANKS, min_size=1, max_size=16))
def test_blanks_between_requests_and_around_params_are_ignored(
    requests: list[Request], blanks: list[str]
) -> None:
    pads = iter(blanks * 100)
    text = ""
    for r in requests:
        inner = ",".join(f"{next(pads)}{p}{next(pads)}" for p in r.params) or next(pads)
        text += f"{next(pads)}{r.module}:{r.device}.{r.function}=({inner})"
    text += next(pads) + "\r"
    assert parse_message(text.encode()) == ParsedMessage(tuple(requests), None)


def _reference_parse(text: str, max_requests: int = 256) -> ParsedMessage:
    """The same grammar with the slow scanner alone: the fast path must agree with it."""
    if text.endswith("\r"):
        text = text[:-1]
    out: list[Request] = []
    pos = _skip_blanks(text, 0)
    while pos < len(text):
        if len(out) >= max_requests:
            return ParsedMessage(tuple(out), syntax_error(
                f"too many requests in one message; at most {max_requests}"))
        got = _scan_request(text, pos)
        if isinstance(got, str):
            return ParsedMessage(tuple(out), syntax_error(got))
        request, pos = got
        out.append(request)
        pos = _skip_blanks(text, pos)
    return ParsedMessage(tuple(out), None)


MCP_JUNK = st.text(alphabet="ab_Z09:.=(),+- \t\r\n\x00\xe9#;", max_size=200)
SEMI_VALID = st.lists(
    st.one_of(REQUEST.map(format_request), MCP_JUNK, BLANKS), max_size=8
).map("".join)


def _check_invariants(p: ParsedMessage, max_requests: int = 256) -> None:
    assert isinstance(p, ParsedMessage)
    assert len(p.requests) <= max_requests
    for r in p.requests:
        for name in (r.module, r.device, r.function):
            assert re.fullmatch(r"[A-Za-z0-9_]{1,32}", name)
        for t in r.params:
            assert re.fullmatch(r"[A-Za-z0-9_.+\-]{1,64}", t)
    if p.syntax_error is not None:
        d = detail(p)
        assert d
        assert_clean(d)


@PROPS
@given(st.binary(max_size=400))
def test_parse_never_raises_on_bytes(data: bytes) -> None:
    _check_invariants(parse_message(data))


@PROPS
@given(st.one_of(MCP_JUNK, SEMI_VALID))
def test_parse_never_raises_on_mcp_like_text(text: str) -> None:
    p = parse_message(text.encode("latin-1"))
    _check_invariants(p)
    assert p == _reference_parse(text)


@PROPS
@given(SEMI_VALID, st.integers(min_value=1, max_value=4))
def test_max_requests_agrees_with_reference(text: str, limit: int) -> None:
    p = parse_message(text.encode("latin-1"), max_requests=limit)
    _check_invariants(p, limit)
    assert p == _reference_parse(text, limit)


def _not_a_number(s: str) -> bool:
    return not re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", s)


VALUE_TEXT = st.text(
    alphabet=st.characters(min_codepoint=32, max_codepoint=126, exclude_characters=",()"),
    min_size=1, max_size=30,
).filter(lambda s: s == s.strip(" \t") and _not_a_number(s))
VALUE = st.one_of(
    st.integers(min_value=-(10**12), max_value=10**12),
    st.floats(allow_nan=False, allow_infinity=False, min_value=-1e9, max_value=1e9),
    st.booleans(),
    VALUE_TEXT,
)
RESPONSE = st.builds(Response, NAME, NAME, NAME, st.lists(VALUE, max_size=5).map(tuple))


def _as_parsed(v: object) -> object:
    if isinstance(v, bool):
        return int(v)
    if isinstance(v, float):
        return float(format_value(v))
    return v


@PROPS
@given(st.lists(RESPONSE, max_size=10))
def test_format_then_parse_responses_round_trips(responses: list[Response]) -> None:
    line = format_responses(responses)
    expected = [Response(r.module, r.device, r.prop, tuple(_as_parsed(v) for v in r.values))
                for r in responses]
    got = parse_response_line(line)
    assert got == expected
    for g, e in zip(got, expected, strict=True):
        assert [type(v) for v in g.values] == [type(v) for v in e.values]


@PROPS
@given(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e12, max_value=1e12))
def test_format_value_float_shape(x: float) -> None:
    text = format_value(x)
    assert re.fullmatch(r"-?\d+\.\d{1,3}", text), text
    assert text == "0.0" or not text.endswith("0") or text.endswith(".0")
    assert text != "-0.0"
    assert abs(float(text) - x) <= 0.0005 + abs(x) * 1e-15


def _split_whole(stream: bytes, max_line: int) -> tuple[list[bytes | TooLong], int]:
    *lines, rest = stream.split(b"\n")
    out: list[bytes | TooLong] = []
    for raw in lines:
        body = raw[:-1] if raw.endswith(b"\r") else raw
        out.append(TooLong(len(raw)) if len(body) > max_line else body)
    pending = len(rest) if len(rest) <= max_line + (1 if rest.endswith(b"\r") else 0) else 0
    return out, pending


@PROPS
@given(
    st.binary(max_size=300).map(lambda b: b.replace(b"\x01", b"\n").replace(b"\x02", b"\r")),
    st.lists(st.integers(min_value=0, max_value=300), max_size=20),
    st.integers(min_value=1, max_value=12),
)
def test_splitter_any_chunking_matches_whole_split(
    stream: bytes, cuts: list[int], max_line: int
) -> None:
    points = sorted({min(c, len(stream)) for c in cuts})
    chunks = [stream[a:b] for a, b in zip([0, *points], [*points, len(stream)], strict=True)]
    s = LineSplitter(max_line=max_line)
    out: list[bytes | TooLong] = []
    for c in chunks:
        out += s.feed(c)
        assert s.pending <= max_line + 1
    expected, pending = _split_whole(stream, max_line)
    assert out == expected
    assert s.pending == pending


def test_the_splitter_is_empty_only_between_messages() -> None:
    s = LineSplitter(max_line=8)
    assert s.empty
    assert s.feed(b"a:b.c=()\n") == [b"a:b.c=()"] and s.empty
    s.feed(b"a:b")
    assert not s.empty
    s.feed(b".c=()\n")
    assert s.empty
    s.feed(b"x" * 20)  # too long: discarded until its newline
    assert not s.empty
    s.feed(b"\n")
    assert s.empty
