"""Hostile-input fuzzing (issue 5): shared strategies and an independent MCP oracle.

The oracle is written from SPEC section 2 alone, character by character, without the
parser's regexes: where it and `ramp.mcp.protocol` disagree, one of them is wrong, and the
fuzz tests say which message showed it. It also predicts, for the demo config of
`tests.harness` (modules `demo` and `arm`: one motor, one lamp each), which responses every
request must produce: error code, get/describe rows, or nothing for an accepted action.

`RAMP_FUZZ_EXAMPLES` scales every example count: the default keeps each file well under
20 s; `make fuzz` sets 20000.
"""

from __future__ import annotations

import math
import os
import string
from collections.abc import Callable
from dataclasses import dataclass

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from ramp.mcp.messages import Response

EXAMPLES = max(1, int(os.environ.get("RAMP_FUZZ_EXAMPLES", "200")))


def fuzz_settings(fraction: float = 1.0, floor: int = 5) -> settings:
    """Hypothesis settings scaled by RAMP_FUZZ_EXAMPLES; no deadline (2 shared cores)."""
    return settings(
        max_examples=max(floor, int(EXAMPLES * fraction)),
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                               HealthCheck.filter_too_much,
                               HealthCheck.function_scoped_fixture],
    )


def fuzz_timeout(per_example_s: float, fraction: float = 1.0, floor: float = 60.0) -> float:
    """A pytest-timeout that grows with the example count, for the long `make fuzz` run."""
    return max(floor, per_example_s * EXAMPLES * fraction * 3)


# --------------------------------------------------------------------------- the grammar

MAX_NAME = 32
MAX_PARAM = 64
MAX_REQUESTS = 256
NAME_CHARS = frozenset(string.ascii_letters + string.digits + "_")
PARAM_CHARS = NAME_CHARS | frozenset(".+-")
BLANKS = " \t"


@dataclass(frozen=True)
class Ref:
    """What the SPEC says one message contains: its requests, and whether parsing stopped."""

    requests: tuple[tuple[str, str, str, tuple[str, ...]], ...]
    syntax_error: bool


def reference_parse(line: bytes, max_requests: int = MAX_REQUESTS) -> Ref:
    """SPEC section 2, walked one character at a time (a message without its `\\n`)."""
    text = line.decode("latin-1")
    if text.endswith("\r"):
        text = text[:-1]
    n = len(text)
    out: list[tuple[str, str, str, tuple[str, ...]]] = []

    def skip(i: int) -> int:
        while i < n and text[i] in BLANKS:
            i += 1
        return i

    def run(i: int, chars: frozenset[str]) -> int:
        while i < n and text[i] in chars:
            i += 1
        return i

    def done(error: bool) -> Ref:
        return Ref(tuple(out), error)

    i = 0
    while True:
        i = skip(i)
        if i >= n:
            return done(False)
        if len(out) >= max_requests:
            return done(True)
        names = []
        for sep in (":", ".", "=("):
            j = run(i, NAME_CHARS)
            if not 0 < j - i <= MAX_NAME or text[j:j + len(sep)] != sep:
                return done(True)
            names.append(text[i:j])
            i = j + len(sep)
        params: list[str] = []
        i = skip(i)
        if i < n and text[i] == ")":
            out.append((names[0], names[1], names[2], ()))
            i += 1
            continue
        while True:
            i = skip(i)
            j = run(i, PARAM_CHARS)
            if not 0 < j - i <= MAX_PARAM:
                return done(True)
            params.append(text[i:j])
            i = skip(j)
            if i >= n:
                return done(True)
            if text[i] == ")":
                i += 1
                break
            if text[i] != ",":
                return done(True)
            i += 1
        out.append((names[0], names[1], names[2], tuple(params)))


def reference_split(stream: bytes, max_line: int) -> list[bytes | None]:
    """Complete messages of a byte stream; None for one longer than `max_line` (too_long)."""
    parts = stream.split(b"\n")[:-1]  # the part after the last `\n` is not a message yet
    out: list[bytes | None] = []
    for p in parts:
        body = p[:-1] if p.endswith(b"\r") else p
        out.append(None if len(body) > max_line else body)
    return out


# --------------------------------------------------------------------------- number oracles


def _digits(s: str) -> bool:
    return bool(s) and all(c in string.digits for c in s)


def spec_int(token: str) -> int | None:
    """An int in decimal with an optional sign (SPEC 2), else None."""
    body = token[1:] if token[:1] in "+-" else token
    return int(token) if _digits(body) else None


def spec_float(token: str) -> float | None:
    """A finite float in decimal or exponent form, or an int literal; else None."""
    body = token[1:] if token[:1] in "+-" else token
    mant, _, exp = body.partition("e") if "e" in body else body.partition("E")
    if "e" in body or "E" in body:
        e = exp[1:] if exp[:1] in "+-" else exp
        if not _digits(e):
            return None
    whole, dot, frac = mant.partition(".")
    if not (_digits(whole) or (dot and _digits(frac))):
        return None
    if (whole and not _digits(whole)) or (frac and not _digits(frac)):
        return None
    v = float(token)
    return v if math.isfinite(v) else None


def spec_name(token: str) -> str | None:
    ok = 0 < len(token) <= 32 and all(c in NAME_CHARS or c == "-" for c in token)
    return token if ok and token.lower() != "none" else None


def in_range(lo: float, hi: float) -> Callable[[float | None], bool]:
    return lambda v: v is not None and lo <= v <= hi


# --------------------------------------------------------------------------- demo oracle

# Each function of the demo config: (parameter checks, kind). A check takes the token.
Check = Callable[[str], bool]

def spec_int_in(lo: int, hi: int) -> Check:
    return lambda t: in_range(lo, hi)(spec_int(t))


_INT_VEL = spec_int_in(-100, 100)
_FLAG: Check = lambda t: t in ("0", "1")  # noqa: E731
# SPEC 2.1 says 0 < t <= 60; the watchdog refuses less than 0.05 s (issue 9, item 7)
_TIMEOUT: Check = lambda t: (v := spec_float(t)) is not None and 0.05 <= v <= 60  # noqa: E731
_NAME: Check = lambda t: spec_name(t) is not None  # noqa: E731

DEMO_TABLE: dict[str, dict[tuple[str, str], tuple[tuple[Check, ...], str]]] = {
    "robot": {
        ("robot", "get"): ((), "read"), ("robot", "stop"): ((), "stop"),
        ("robot", "describe"): ((), "read"), ("robot", "modules"): ((), "read"),
        ("watchdog", "timeout"): ((_TIMEOUT,), "state"),
        ("control", "acquire"): ((_NAME,), "control"),
        ("control", "release"): ((), "state"),
    },
}
for _m in ("demo", "arm"):
    DEMO_TABLE[_m] = {
        (_m, "get"): ((), "read"), (_m, "stop"): ((), "stop"), (_m, "describe"): ((), "read"),
        ("motor", "vel"): ((_INT_VEL,), "motion"), ("lamp", "on"): ((_FLAG,), "state"),
    }

Key = tuple[str, ...]
RequestTuple = tuple[str, str, str, tuple[str, ...]]


class DemoOracle:
    """Predicts the responses of each request on the demo config, arbitration included.

    `rows` holds the row keys of every read function, measured once (their values vary,
    their keys do not). Requests must be fed in the order the supervisor handles them.
    """

    def __init__(self, rows: dict[tuple[str, str, str], list[Key]]) -> None:
        self.rows = rows
        self.owner: object | None = None

    def expect(self, client: object, req: RequestTuple) -> list[Key]:
        """The responses one request must produce, as (module, device, prop[, error code])."""
        module, device, function, params = req
        table = DEMO_TABLE.get(module)
        if table is None:
            return [(module, device, "error", "unknown_module")]
        entry = table.get((device, function))
        if entry is None:
            if not any(d == device for d, _ in table):
                return [(module, device, "error", "unknown_device")]
            return [(module, device, "error", "unknown_function")]
        checks, kind = entry
        if len(params) != len(checks) or not all(
                c(p) for c, p in zip(checks, params, strict=True)):
            return [(module, device, "error", "bad_params")]
        if kind in ("motion", "state") and self.owner not in (None, client):
            return [(module, device, "error", "not_owner")]
        if (device, function) == ("control", "acquire"):
            self.owner = client
        elif (device, function) == ("control", "release") and self.owner is client:
            self.owner = None
        if kind == "read":
            return self.rows[(module, device, function)]
        return []

    def expect_message(self, client: object, body: bytes | None) -> list[Key]:
        """Every response of one message (None: it was too long)."""
        if body is None:
            return [("robot", "mcp", "error", "too_long")]
        # Through the server the SPEC sets no request count: `max_line` bounds a message, and
        # every request that fits in it is handled (the supervisor sizes the parser's limit).
        ref = reference_parse(body, max_requests=len(body) + 1)
        out = [k for req in ref.requests for k in self.expect(client, req)]
        if ref.syntax_error:
            out.append(("robot", "mcp", "error", "syntax"))
        return out


def response_keys(responses: list[Response]) -> list[Key]:
    """Keys of parsed responses, in the shape `expected_keys` returns."""
    out: list[Key] = []
    for r in responses:
        if r.prop == "error":
            out.append((r.module, r.device, "error", str(r.values[0])))
        else:
            out.append((r.module, r.device, r.prop))
    return out


# --------------------------------------------------------------------------- strategies

EDGE_NUMBERS = [
    "0", "-0", "+0", "00", "-00", "0.0", "-0.0", "+0.0", ".0", "0.", "1", "-1", "+1",
    "100", "-100", "+100", "101", "-101", "99", "0100", "-0100", "00000000000000000100",
    "100.0", "99.5", "1e2", "1E2", "1e+2", "1.0e2", "60", "60.0", "60.0000001", "6e1", "59.999",
    "0.001", "1e-3", "1e-300", "4.9e-324", "5e-324", "2.2250738585072014e-308", "1e-400",
    "0.5", ".5", "5.", "1.0", "1.0000000001", "0.9999999999", "0.99", "0.01", "0.05", "0.049",
    "9223372036854775807", "-9223372036854775808", "9223372036854775808",
    "-9223372036854775809", "18446744073709551615", "18446744073709551616",
    "2147483647", "-2147483648", "4294967296",
    "1e308", "-1e308", "1.7976931348623157e308", "1.7976931348623158e308", "1e309",
    "-1e309", "1e999999999", "1" * 64, "9" * 64, "-" + "9" * 63,
    "nan", "NaN", "-nan", "+nan", "NAN", "inf", "-inf", "+inf", "Inf", "INF", "Infinity",
    "-Infinity", "infinity", "0x10", "0X10", "0b1", "0o7", "1_000", "1_0", "_1", "1_",
    "1e", "e1", "1e+", "1e-", ".", "-", "+", "+-1", "-+1", "--1", "++1", "1..0", "1.0.0",
    ".e1", "1.e1", "e", "E", "0e0", "-0e-0", "1e0001", "1e-0", "1.5e3", "1.5E-3",
]

NAMES = ["robot", "demo", "arm", "motor", "lamp", "watchdog", "control", "get", "stop",
         "describe", "modules", "vel", "on", "timeout", "acquire", "release", "base", "ble",
         "lf_wheel", "error", "mcp", "x", "_", "0", "ROBOT", "Demo", "n" * 32, "n" * 33]

name_text = st.one_of(
    st.sampled_from(NAMES),
    st.text(alphabet=string.ascii_letters + string.digits + "_", min_size=1, max_size=34),
)
token_text = st.one_of(
    st.sampled_from(EDGE_NUMBERS),
    st.integers(min_value=-(2 ** 70), max_value=2 ** 70).map(str),
    st.integers(min_value=-120, max_value=120).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(min_value=-2, max_value=2).map(repr),
    st.from_regex(r"\A[+-]?[0-9]{0,3}\.?[0-9]{0,3}([eE][+-]?[0-9]{1,4})?\Z"),
    st.text(alphabet=string.ascii_letters + string.digits + "_.+-", min_size=1, max_size=66),
    st.sampled_from(["none", "NONE", "op", "autonomy", "a-b", "a" * 32, "a" * 33]),
).filter(bool)  # an empty parameter is a syntax error, tested with the garbage
blank = st.text(alphabet=" \t", max_size=3)


#: Parameters each demo function accepts, so requests get past the checks often enough to
#: exercise arbitration and the watchdog, not only the error paths.
VALID_PARAMS: dict[tuple[str, str], st.SearchStrategy[list[str]]] = {
    ("watchdog", "timeout"): st.sampled_from(["0.5", "1", "60", "0.05", "2.5e1"]).map(
        lambda t: [t]),
    ("control", "acquire"): st.sampled_from(["op", "autonomy", "A-1", "x" * 32]).map(
        lambda t: [t]),
    ("motor", "vel"): st.integers(-100, 100).map(lambda v: [str(v)]),
    ("lamp", "on"): st.sampled_from([["0"], ["1"]]),
}


@st.composite
def request_text(draw: st.DrawFn, max_params: int = 4) -> str:
    """One request, mostly well-formed: blanks where the SPEC allows them.

    Names are known to the demo tables at every depth (module, device, function) or not, so
    each check of SPEC 2's order is reached: unknown module, device, function, bad params,
    ownership, and success.
    """
    module, device, function = draw(name_text), draw(name_text), draw(name_text)
    depth = draw(st.integers(0, 5))
    if depth >= 1:
        module = draw(st.sampled_from(["robot", "demo", "arm"]))
    if depth >= 2:
        known_device, known_function = draw(st.sampled_from(sorted(DEMO_TABLE[module])))
        device = known_device
        if depth >= 3:
            function = known_function
    params = draw(st.lists(token_text, max_size=max_params))
    if depth >= 4 and (device, function) in VALID_PARAMS:
        params = draw(VALID_PARAMS[(device, function)])
    elif depth >= 4:
        params = []
    inner = ",".join(draw(blank) + p + draw(blank) for p in params) or draw(blank)
    return f"{draw(blank)}{module}:{device}.{function}=({inner})"


HOSTILE = ":.=(),\t \r\x00\x7f\xff\xc3\xa9" + "ab_19+-"
garbage_text = st.one_of(
    st.binary(max_size=40).map(lambda b: b.decode("latin-1")),
    st.text(alphabet=HOSTILE, max_size=40),
    st.sampled_from(["(", ")", "=()", ":", "a:b", "a:b.", "a:b.c", "a:b.c=", "a:b.c=(",
                     "a:b.c=(1", "a:b.c=(1,", "a:b.c=(,)", "a:b.c=(1 2)", "a :b.c=()",
                     "\x00", "\xff", "é", "\r", "\t", " ", "a:b.c=()x"]),
)


@st.composite
def message_text(draw: st.DrawFn) -> str:
    """One message body (no `\\n`): requests and garbage in any order."""
    parts = draw(st.lists(st.one_of(request_text(), request_text(), garbage_text), max_size=6))
    body = "".join(parts).replace("\n", "")
    if draw(st.integers(0, 9)) == 0:
        body += "\r"
    return body


def latin1(text: str) -> bytes:
    """Text whose code points are all < 256 as the bytes they stand for."""
    return text.encode("latin-1")


@st.composite
def streams(draw: st.DrawFn, max_messages: int = 12) -> list[bytes]:
    """Message bodies: MCP-like text, random bytes, heartbeats and over-long lines."""
    bodies = draw(st.lists(st.one_of(
        message_text().map(latin1),
        message_text().map(latin1),
        st.binary(max_size=80).map(lambda b: b.replace(b"\n", b"")),
        st.sampled_from([b"", b"\r", b" ", b"\t\t"]),
        st.integers(4090, 4200).map(lambda n: (b"demo:motor.vel=(1)" * 300)[:n]),
        st.integers(4090, 4200).map(lambda n: b"x" * n + b"\r"),
    ), max_size=max_messages))
    return bodies


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    out, prev = [], 0
    for p in [*points, len(data)]:
        out.append(data[prev:p])
        prev = p
    return out
