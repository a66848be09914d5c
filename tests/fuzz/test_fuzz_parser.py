"""Hostile input at the codec and routing level, no sockets (issue 5, part 1).

Random bytes, huge lines, NUL and non-ASCII, thousands of requests in one message, long
parameter lists, numbers at and past every limit, interleaved streams. Properties: nothing
raises, the parser agrees with an independent reading of the SPEC, every message gets exactly
one response line whose responses the oracle predicts, and output stays bounded.
"""

from __future__ import annotations

import math
import string
from collections.abc import Iterator

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from ramp.layers.robot_distribution import Client
from ramp.mcp.messages import Response, clean_detail
from ramp.mcp.protocol import (
    LineSplitter,
    TooLong,
    format_responses,
    parse_message,
    parse_response_line,
)
from tests.fuzz import (
    EDGE_NUMBERS,
    EXAMPLES,
    MAX_REQUESTS,
    DemoOracle,
    Key,
    chunked,
    fuzz_settings,
    fuzz_timeout,
    garbage_text,
    latin1,
    message_text,
    reference_parse,
    reference_split,
    request_text,
    response_keys,
    spec_float,
    spec_int,
    streams,
    token_text,
)
from tests.harness import Harness, SimHarness

pytestmark = pytest.mark.timeout(fuzz_timeout(0.05))

#: No single response may be longer than this: names are at most 32 characters and error
#: details at most 200, so nothing a client sends can make one response grow.
MAX_RESPONSE = 32 + 1 + 32 + 1 + 32 + 2 + 260 + 1


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def demo() -> Iterator[Harness]:
    h = Harness()
    yield h
    h.close()


@pytest.fixture(scope="module")
def marte() -> Iterator[SimHarness]:
    h = SimHarness()
    yield h
    h.close()


def answer(h: Harness, client: Client, msg: bytes | TooLong) -> bytes:
    """What the server writes for one message (parsed, handed down, answered in one line)."""
    return h.sup.server.answer_message(client, msg)


def ask(h: Harness, client: Client, text: str) -> str:
    return answer(h, client, text.encode()).decode().rstrip("\n")


def row_keys(h: Harness) -> dict[tuple[str, str, str], list[Key]]:
    """The keys of every read function's rows on the demo config, measured once."""
    c = Client("rows")
    rows = {}
    for module in ("robot", "demo", "arm"):
        fns = ["get", "describe"] + (["modules"] if module == "robot" else [])
        for fn in fns:
            line = answer(h, c, f"{module}:{module}.{fn}=()".encode())
            rows[(module, module, fn)] = response_keys(parse_response_line(line))
    return rows


def check_line(out: bytes, n_requests: int, max_rows: int) -> list[Response]:
    """One response line: ASCII, one `\\n` at its end, well-formed, bounded."""
    assert out.endswith(b"\n") and out.count(b"\n") == 1, out[:200]
    assert out.isascii()
    assert len(out) <= (n_requests * max_rows + 1) * MAX_RESPONSE + 1
    responses = parse_response_line(out)
    for r in responses:
        if r.prop == "error":
            detail = str(r.values[1]) if len(r.values) > 1 else ""
            assert len(r.values) == 2 and clean_detail(detail) == detail, r
    return responses


# --------------------------------------------------------------------------- the parser alone


def check_parse(line: bytes) -> None:
    parsed = parse_message(line)  # must not raise, whatever the bytes
    ref = reference_parse(line)
    got = tuple((r.module, r.device, r.function, r.params) for r in parsed.requests)
    assert got == ref.requests, line[:200]
    assert (parsed.syntax_error is not None) == ref.syntax_error, (line[:200], parsed)
    assert len(parsed.requests) <= MAX_REQUESTS
    if parsed.syntax_error is not None:
        e = parsed.syntax_error
        assert (e.module, e.device, e.prop, e.values[0]) == ("robot", "mcp", "error", "syntax")
        assert clean_detail(str(e.values[1])) == e.values[1]
        assert parse_response_line(format_responses([e])) == [e]
    body = line[:-1] if line.endswith(b"\r") else line
    assert parsed.heartbeat == (not body.strip(b" \t"))


@fuzz_settings()
@given(st.binary(max_size=600))
@example(b"\x00" * 64)
@example(b"\xff\xfe\x80" * 30)
@example("base:base.get=()é".encode())
@example(b"a:b.c=(1)\x00a:b.c=(2)")
@example(b"\r")
@example(b"\r\r")
@example(b" \t \r")
def test_random_bytes_never_raise_and_agree_with_the_spec(data: bytes) -> None:
    check_parse(data.replace(b"\n", b""))


@fuzz_settings()
@given(message_text())
@example("n" * 32 + ":d.f=()" + "n" * 33 + ":d.f=()")
@example("m:" + "d" * 32 + ".f=()m:" + "d" * 33 + ".f=()")
@example("m:d." + "f" * 32 + "=()m:d." + "f" * 33 + "=()")
@example("m:d.f=(" + "1" * 64 + ")m:d.f=(" + "1" * 65 + ")")
@example("m:d.f=( 1 ,\t2\t)  m:d.f=(\t)\tm:d.f=(1 2)")
@example("m :d.f=()")
@example("m:d .f=()")
@example("m:d.f =()")
@example("m:d.f= ()")
@example("m:d.f=(1,,2)")
@example("m:d.f=(,)")
@example("m:d.f=(1,)")
@example("m:d.f=(1")
@example("m:d.f=(1\r)")
@example("m:d.f=()\r\r")
def test_mcp_like_messages_agree_with_the_spec(text: str) -> None:
    check_parse(latin1(text))


@fuzz_settings(0.2)
@given(st.integers(0, 5000), request_text(max_params=1), st.sampled_from(["", " ", "\t"]),
       st.one_of(st.just(""), garbage_text))
@example(256, "a:b.c=()", "", "")
@example(257, "a:b.c=()", "", "")
@example(256, "a:b.c=()", " ", "  \t")
@example(256, "a:b.c=()", "", "x")
@example(5000, "base:base.get=()", "", "")
def test_thousands_of_requests_in_one_message(count: int, req: str, sep: str,
                                              tail: str) -> None:
    line = latin1(sep.join([req] * count) + tail.replace("\n", ""))
    check_parse(line)
    parsed = parse_message(line)
    one = reference_parse(latin1(req))
    if len(one.requests) != 1 or one.syntax_error:
        return
    rest = tail.replace("\n", "").strip(" \t")
    if not rest or count >= MAX_REQUESTS:
        assert len(parsed.requests) == min(count, MAX_REQUESTS)
    if count > MAX_REQUESTS or (count == MAX_REQUESTS and rest):
        assert parsed.syntax_error is not None
        assert "too many requests" in str(parsed.syntax_error.values[1])


@fuzz_settings(0.2)
@given(st.lists(token_text, min_size=1, max_size=3000), st.sampled_from([",", " , ", ",\t"]),
       st.booleans())
def test_long_parameter_lists(tokens: list[str], sep: str, close: bool) -> None:
    line = latin1("demo:motor.vel=(" + sep.join(tokens) + (")" if close else ""))
    check_parse(line)


@fuzz_settings(0.2)
@given(st.integers(0, 200_000), st.sampled_from([b"1", b"a", b" ", b"(", b"\x00", b"\xff",
                                                  b"a:b.c=(", b"a:b.c=()"]))
@example(1 << 20, b"9")
def test_huge_lines_are_bounded_work(size: int, unit: bytes) -> None:
    """A huge line parses (or fails) in one pass; its answer does not grow with it."""
    line = (unit * (size // len(unit) + 1))[:size]
    parsed = parse_message(line)
    assert len(parsed.requests) <= MAX_REQUESTS
    if parsed.syntax_error is not None:
        assert len(format_responses([parsed.syntax_error])) <= MAX_RESPONSE + 1


# --------------------------------------------------------------------------- numbers


@fuzz_settings(2.0)
@given(token_text)
def test_numbers_at_every_limit_on_the_demo_tables(demo: Harness, token: str) -> None:
    """Accepted exactly when the SPEC says; the value lands; a refusal changes nothing."""
    c = Client("numbers")
    h = demo
    before = h.world.motors.get("demo.motor", 0.0)
    resp = ask(h, c, f"demo:motor.vel=({token})")
    v = spec_int(token)
    if len(token) <= 20 and v is not None and -100 <= v <= 100:
        assert resp == ""
        assert h.world.motors["demo.motor"] == pytest.approx(v / 100)
        assert f"demo:motor.vel=({v})" in ask(h, c, "demo:demo.get=()")
    else:
        assert resp == "demo:motor.error=(bad_params,vel takes one int in -100..100)"
        assert h.world.motors.get("demo.motor", 0.0) == before
    ask(h, c, "demo:demo.stop=()")

    old = c.timeout
    resp = ask(h, c, f"robot:watchdog.timeout=({token})")
    f = spec_float(token)
    if f is not None and 0.05 <= f <= 60:
        assert resp == ""
        assert c.timeout == f  # the sender's own (SPEC 2.2)
        assert h.sup.watchdog.timeout == 0.5  # the default for everyone else is unchanged
        shown = f"{f:.3f}".rstrip("0")
        shown = "0.0" if shown in ("0.", "-0.") else shown + ("0" if shown.endswith(".") else "")
        assert f"robot:watchdog.timeout=({shown})" in ask(h, c, "robot:robot.get=()")
        ask(h, c, "robot:watchdog.timeout=(0.5)")
    else:
        assert resp == "robot:watchdog.error=(bad_params,timeout takes one float in 0.05..60)"
        assert c.timeout == old


def test_long_int_with_leading_zeros_is_an_int(demo: Harness) -> None:
    assert ask(demo, Client("z"), "demo:motor.vel=(000000000000000000000100)") == ""


def drive_oracle(s: int, d: float) -> tuple[float, float]:
    """SPEC 2.3, written out again: mix, then scale so the larger magnitude is |s|."""
    r = math.radians(math.fmod(d, 360.0))
    left, right = s * (math.cos(r) + math.sin(r)), s * (math.cos(r) - math.sin(r))
    big = max(abs(left), abs(right))
    if big == 0:
        return 0.0, 0.0
    return left * abs(s) / big, right * abs(s) / big


def wheel(get: str, name: str) -> int:
    start = get.index(f"base:{name}.vel=(") + len(f"base:{name}.vel=(")
    return int(get[start:get.index(")", start)])


@fuzz_settings(0.5)
@given(st.one_of(token_text, st.integers(-100, 100).map(str)),
       st.one_of(token_text, st.floats(allow_nan=False, allow_infinity=False).map(repr)))
@example("50", "1e308")
@example("100", "1.7976931348623157e308")
@example("-100", "-1.7976931348623157e308")
@example("100", "4.9e-324")
@example("100", "-0")
@example("100", "45")
@example("100", "-90")
@example("100", "720")
@example("100", "1e16")
@example("-9223372036854775808", "0")
def test_base_drive_at_the_limits(marte: SimHarness, speed: str, direction: str) -> None:
    c = Client("drive")
    resp = ask(marte, c, f"base:base.drive=({speed},{direction})")
    s, d = spec_int(speed), spec_float(direction)
    ok = len(speed) <= 20 and s is not None and -100 <= s <= 100 and d is not None
    if not ok:
        assert resp == ("base:base.error=(bad_params,drive takes two parameters: int in "
                        "-100..100 and float)")
        return
    assert resp == ""
    assert s is not None and d is not None
    get = ask(marte, c, "base:base.get=()")
    left, right = drive_oracle(s, d)
    for name, want in (("lf_wheel", left), ("lb_wheel", left), ("rf_wheel", right),
                       ("rb_wheel", right)):
        assert abs(wheel(get, name) - want) <= 0.5 + 1e-6, (speed, direction, get)
    ask(marte, c, "base:base.stop=()")


@fuzz_settings(0.5)
@given(token_text)
@example("1e-400")
@example("-0")
@example("1.0000000001")
@example("-1e-300")
def test_ble_numbers_at_the_limits(marte: SimHarness, token: str) -> None:
    c = Client("ble")
    f, i = spec_float(token), spec_int(token)
    pos_ok = f is not None and 0.0 <= f <= 1.0
    assert ask(marte, c, f"ble:lift.pos=({token})") == (
        "" if pos_ok else "ble:lift.error=(bad_params,pos takes one float in 0..1)")
    vel_ok = len(token) <= 20 and i is not None and -100 <= i <= 100
    assert ask(marte, c, f"ble:chain.vel=({token})") == (
        "" if vel_ok else "ble:chain.error=(bad_params,vel takes one int in -100..100)")
    if vel_ok:
        assert f"ble:chain.vel=({i})" in ask(marte, c, "ble:ble.get=()")
    assert ask(marte, c, "ble:ble.stop=()") == ""


def marte_tables(h: SimHarness) -> tuple[list[tuple[str, str, str, tuple[str, ...]]],
                                          dict[tuple[str, str, str], str]]:
    """From describe: (module, device, function, parameter types) of every MARTE request,
    and the type (int, float, name) of every get property."""
    c = Client("describe")
    functions, types = [], {}
    for module in ("robot", "base", "ble"):
        for r in parse_response_line(answer(h, c, f"{module}:{module}.describe=()".encode())):
            if r.prop == "function":
                functions.append((r.module, r.device, str(r.values[0]),
                                  tuple(str(v) for v in r.values[1:])))
            elif r.prop == "property":
                types[(r.module, r.device, str(r.values[0]))] = str(r.values[1])
    return functions, types


def valid_token(kind: str) -> st.SearchStrategy[str]:
    """A token the SPEC accepts for a describe type such as `int -100..100` or `float 0..1`."""
    if kind == "name":
        return st.sampled_from(["op", "autonomy", "x-1"])
    if kind.startswith("int"):
        ilo, ihi = (int(x) for x in kind.split(" ")[1].split(".."))
        return st.integers(ilo, ihi).map(str)
    if kind == "float":
        return st.floats(allow_nan=False, allow_infinity=False).map(repr)
    lo_text, hi_text = kind.split(" ")[1].split("..")
    lo = float(lo_text.lstrip(">"))
    return st.floats(lo, float(hi_text), exclude_min=lo_text.startswith(">")).map(repr)


MARTE_CLIENT = Client("marte")
#: The kinds describe publishes (README, "Talking to the robot").
SPEC_KINDS = ("motion", "stop", "state", "read", "control")


@fuzz_settings(0.3)
@given(st.data())
def test_marte_tables_survive_anything(marte: SimHarness, data: st.DataObject) -> None:
    """Any request the MARTE tables know, with valid or hostile parameters, while simulated
    time runs the physics: one parseable line per message, every refusal is an error, every
    value finite, and nothing raises inside the loop."""
    h = marte
    functions, types = marte_tables(h)
    c = MARTE_CLIENT  # one client throughout: arbitration state must not leak between runs
    ask(h, c, "robot:robot.stop=()robot:control.release=()robot:watchdog.timeout=(1)")
    for _ in range(data.draw(st.integers(1, 6))):
        reqs = []
        for _ in range(data.draw(st.integers(0, 5))):
            module, device, function, kinds = data.draw(st.sampled_from(functions))
            if data.draw(st.booleans()):
                tokens = [data.draw(valid_token(k)) for k in kinds]
            else:
                tokens = data.draw(st.lists(token_text, max_size=3))
            reqs.append(f"{module}:{device}.{function}=({','.join(tokens)})")
        line = answer(h, c, "".join(reqs).encode())
        responses = check_line(line, len(reqs), 40)
        for r in responses:
            if r.prop == "error":  # interlocked: MARTE's rules (the bin raised, the chain)
                assert r.values[0] in ("bad_params", "syntax", "interlocked"), r
                continue
            kind = types.get((r.module, r.device, r.prop))
            if kind is None:  # describe and robot.modules rows; every get row is described
                assert r.prop in ("function", "property", "module", "modules", "kind",
                                  "rule", "message"), r
            if r.prop == "kind":  # a function's kind: a function describe lists, a known kind
                assert len(r.values) == 2 and r.values[1] in SPEC_KINDS, r
                assert any(f[:3] == (r.module, r.device, r.values[0]) for f in functions), r
            if kind == "int":
                assert all(type(v) is int for v in r.values), r
            elif kind == "float":
                assert all(isinstance(v, int | float) and math.isfinite(v) for v in r.values), r
        h.advance(data.draw(st.sampled_from([0.0, 0.01, 0.1, 0.5])))
    assert all(t.errors == 0 for t in h.sup.scheduler.tasks)
    assert all(slot.state == "ok" for slot in h.sup.slots.values())


# --------------------------------------------------------------------------- whole messages


EVERY_CHECK = [  # each check of SPEC 2's order, failing and passing, once
    b"nope:x.y=()demo:wheel.vel=(1)demo:motor.spin=()demo:motor.vel=(101)demo:motor.vel=(1,2)",
    b"robot:watchdog.timeout=(0)robot:watchdog.timeout=(60)robot:watchdog.timeout=(60.001)",
    b"robot:control.acquire=(none)robot:control.acquire=(NONE)robot:control.acquire=(op)",
    b"demo:motor.vel=(100)demo:lamp.on=(1)demo:demo.get=()arm:arm.describe=()",
    b"robot:robot.modules=()robot:robot.get=()robot:robot.describe=()robot:control.release=()",
    b"demo:demo.stop=()robot:robot.stop=()demo:demo.stop=(1)demo:lamp.on=(2)arm:arm.get=(0)",
    b"a:b.c=()" * 512,  # as many requests as max_line holds: all answered
]


@fuzz_settings(0.5)
@given(streams(), st.lists(st.integers(0, 1 << 16), max_size=20),
       st.sampled_from([b"\n", b"\r\n"]), st.binary(max_size=30))
@example(EVERY_CHECK, [], b"\n", b"")
@example(EVERY_CHECK, [1, 7, 100, 101, 102], b"\r\n", b"demo:motor.vel=(5)")
@example([b"x" * 4096, b"x" * 4097, b"x" * 4096 + b"\r", b"x" * 4097 + b"\r"], [4095, 4096],
         b"\n", b"")
def test_every_message_gets_exactly_one_predicted_line(
        demo: Harness, bodies: list[bytes], cuts: list[int], eol: bytes, tail: bytes) -> None:
    """Splitter, parser, routing and codec together, fed in arbitrary chunks."""
    h = demo
    max_line = h.config.server.max_line
    rows = row_keys(h)
    max_rows = max(len(v) for v in rows.values())
    oracle = DemoOracle(rows)
    client = Client("stream")
    stream = b"".join(b + eol for b in bodies) + tail.replace(b"\n", b"")
    expected = reference_split(stream, max_line)
    splitter = LineSplitter(max_line)
    lines: list[bytes] = []
    for piece in chunked(stream, cuts):
        for msg in splitter.feed(piece):
            lines.append(answer(h, client, msg))
        assert splitter.pending <= max_line + 1
    assert len(lines) == len(expected) == len(bodies)
    for body, out in zip(expected, lines, strict=True):
        n = len(reference_parse(body, len(body) + 1).requests) if body is not None else 0
        got = response_keys(check_line(out, n, max_rows))
        assert got == oracle.expect_message(client, body), (body, out)
    ask(h, client, "robot:control.release=()robot:robot.stop=()")


TAKEOVER = [  # two clients: acquire, refusals, release by the wrong one, takeover
    [b"robot:control.acquire=(auto)demo:motor.vel=(50)", b"demo:motor.vel=(60)",
     b"robot:control.release=()", b"robot:watchdog.timeout=(2)"],
    [b"demo:motor.vel=(10)demo:lamp.on=(1)robot:control.release=()demo:demo.get=()",
     b"robot:watchdog.timeout=(3)robot:robot.stop=()demo:demo.stop=()",
     b"robot:control.acquire=(op)demo:motor.vel=(10)", b"robot:control.release=()"],
]


@fuzz_settings(0.3)
@given(st.lists(streams(6), min_size=2, max_size=4),
       st.lists(st.tuples(st.integers(0, 3), st.integers(1, 64)), min_size=1, max_size=200))
@example(TAKEOVER, [(0, 49), (1, 200), (1, 64), (0, 20), (1, 48), (0, 80), (1, 100)])
@example(TAKEOVER, [(0, 100), (1, 500), (0, 500)])
def test_interleaved_clients_each_get_their_own_lines(
        demo: Harness, per_client: list[list[bytes]], schedule: list[tuple[int, int]]) -> None:
    """Partial messages of several clients interleaved: each stream stays whole and in step;
    arbitration between them follows the SPEC (the oracle tracks the owner)."""
    h = demo
    max_line = h.config.server.max_line
    rows = row_keys(h)
    oracle = DemoOracle(rows)
    clients = [Client(f"c{i}") for i in range(len(per_client))]
    streams_ = [b"".join(b + b"\n" for b in bodies) for bodies in per_client]
    splitters = [LineSplitter(max_line) for _ in clients]
    sent = [0] * len(clients)
    got: list[list[list[Key]]] = [[] for _ in clients]
    want: list[list[list[Key]]] = [[] for _ in clients]
    expected = [reference_split(s, max_line) for s in streams_]

    def feed(i: int, n: int) -> None:
        piece = streams_[i][sent[i]:sent[i] + n]
        sent[i] += len(piece)
        for msg in splitters[i].feed(piece):
            body = expected[i][len(got[i])]
            want[i].append(oracle.expect_message(clients[i], body))
            out = answer(h, clients[i], msg)
            nreq = len(reference_parse(body, len(body) + 1).requests) if body is not None else 0
            got[i].append(response_keys(check_line(out, nreq, max(map(len, rows.values())))))

    for who, n in schedule:
        feed(who % len(clients), n)
    for i in range(len(clients)):  # the rest of every stream, so every message completes
        feed(i, len(streams_[i]))
    for i in range(len(clients)):
        assert len(got[i]) == len(per_client[i])
        assert got[i] == want[i]
    for c in clients:
        ask(h, c, "robot:control.release=()")
    ask(h, clients[0], "robot:robot.stop=()")


def test_every_edge_number_is_in_the_token_class() -> None:
    """The edge list reaches the parameter checks: no edge is lost as a syntax error."""
    for token in EDGE_NUMBERS:
        if all(c in string.ascii_letters + string.digits + "_.+-" for c in token):
            parsed = parse_message(f"demo:motor.vel=({token})".encode())
            assert parsed.syntax_error is None and parsed.requests[0].params == (token,)


assert EXAMPLES >= 1
