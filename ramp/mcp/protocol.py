"""MCP codec, sans-IO: bytes in, values out, and back (SPEC section 2).

Pure functions and one byte accumulator; transports only move bytes, so every rule here is
tested with byte strings alone. `parse_message` is the server's hot path: a single compiled
regex consumes well-formed requests, and only when it fails does a hand-written scanner walk
the same grammar again to say precisely what is wrong and where.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from numbers import Integral, Real
from typing import NamedTuple

from ramp.errors import ProtocolError
from ramp.mcp.messages import Request, Response, Value, error_response

MAX_NAME = 32
MAX_PARAM = 64
MAX_REQUESTS = 256
MAX_LINE = 4096

_BLANK = " \t"

# One well-formed request, optionally preceded by blanks. The parameter group admits only
# parameter characters, commas and blanks; token rules (non-empty, <= 64, no inner blank)
# are checked on the split text, and any failure falls back to the diagnosing scanner.
_REQUEST = re.compile(
    r"[ \t]*([A-Za-z0-9_]{1,32}):([A-Za-z0-9_]{1,32})\.([A-Za-z0-9_]{1,32})"
    r"=\(([A-Za-z0-9_.+\-, \t]*)\)"
)

# Response side (clients): names of any length, values of printable ASCII except `(` `)`.
_RESPONSE = re.compile(
    r"[ \t]*([A-Za-z0-9_]+):([A-Za-z0-9_]+)\.([A-Za-z0-9_]+)=\(([\x20-\x27\x2a-\x7e]*)\)"
)
# Runs the diagnosing scanner steps over in C rather than a character at a time.
_NAME_RUN = re.compile(r"[A-Za-z0-9_]*")
_PARAM_RUN = re.compile(r"[A-Za-z0-9_.+\-]*")
_BLANK_RUN = re.compile(r"[ \t]*")
# Number forms without overlapping repeats, so a long run of digits cannot backtrack.
_INT_FORM = re.compile(r"[+-]?[0-9]+\Z")
_FLOAT_FORM = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")


class ParsedMessage(NamedTuple):
    """The requests of one message, and the syntax error that stopped parsing, if any.

    A NamedTuple rather than a dataclass: it is built once per message on the hot path.
    """

    requests: tuple[Request, ...]
    syntax_error: Response | None = None

    @property
    def heartbeat(self) -> bool:
        """A message with nothing in it: it only says the client is alive."""
        return not self.requests and self.syntax_error is None


_HEARTBEAT = ParsedMessage(())


@dataclass(frozen=True, slots=True)
class TooLong:
    """Stands in for a message that exceeded `max_line`; its bytes were discarded."""

    length: int


def syntax_error(detail: str) -> Response:
    """`robot:mcp.error=(syntax,detail)`, detail sanitized."""
    return error_response("robot", "mcp", "syntax", detail)


def too_long_response(max_line: int = MAX_LINE) -> Response:
    """The answer to a discarded over-long message, so request and response lines stay paired."""
    return error_response("robot", "mcp", "too_long", f"message longer than {max_line} bytes")


# --------------------------------------------------------------------------- parsing


def parse_message(line: bytes, *, max_requests: int = MAX_REQUESTS) -> ParsedMessage:
    """Split one message (without its `\\n`) into requests; never raises on any bytes.

    Requests before the first unparseable point are returned together with one syntax error;
    the rest of the message is ignored, as the SPEC requires.
    """
    # latin-1 maps every byte to one code point, so columns are byte offsets and decoding
    # cannot fail; every character class below is ASCII, so non-ASCII bytes never match.
    if isinstance(line, bytes | bytearray):
        text = line.decode("latin-1")
    elif isinstance(line, str):
        text = line
    else:
        text = bytes(line).decode("latin-1")
    if text.endswith("\r"):
        text = text[:-1]
    n = len(text)
    if not text.strip(_BLANK):
        return _HEARTBEAT
    pos = 0
    requests: list[Request] = []
    match = _REQUEST.match
    while pos < n:
        if len(requests) >= max_requests:
            if _skip_blanks(text, pos) < n:
                detail = f"too many requests in one message; at most {max_requests}"
                return ParsedMessage(tuple(requests), syntax_error(detail))
            break
        m = match(text, pos)
        if m is not None:
            module, device, function, raw = m.groups()
            params = _split_params(raw) if raw else ()
            if params is not None:
                requests.append(Request(module, device, function, params))
                pos = m.end()
                continue
        pos = _skip_blanks(text, pos)
        if pos >= n:
            break
        scanned = _scan_request(text, pos)
        if isinstance(scanned, str):
            return ParsedMessage(tuple(requests), syntax_error(scanned))
        # The scanner accepted what the regex refused: cannot happen while they agree, but
        # taking the scanner's word keeps the parser total and moving forward.
        request, pos = scanned
        requests.append(request)
    return ParsedMessage(tuple(requests))


def _skip_blanks(text: str, pos: int) -> int:
    return _run_end(_BLANK_RUN, text, pos)


def _run_end(run: re.Pattern[str], text: str, pos: int) -> int:
    """End of the (possibly empty) run of `run`'s characters starting at `pos`."""
    m = run.match(text, pos)
    return pos if m is None else m.end()


def _split_params(raw: str) -> tuple[str, ...] | None:
    """Parameter tokens of a regex-matched list, or None when a token rule is broken."""
    if "," not in raw:
        token = raw.strip(_BLANK)
        if not token:
            return ()
        if len(token) > MAX_PARAM or " " in token or "\t" in token:
            return None
        return (token,)
    tokens = []
    for part in raw.split(","):
        token = part.strip(_BLANK)
        if not token or len(token) > MAX_PARAM or " " in token or "\t" in token:
            return None
        tokens.append(token)
    return tuple(tokens)


def _scan_request(text: str, pos: int) -> tuple[Request, int] | str:
    """Walk one request by hand from `pos`: (request, end) or an operator-readable detail.

    The slow path: it runs only where the regex failed, to name what was expected and the
    1-based column where it was not found.
    """
    n = len(text)
    names: list[str] = []
    for kind, after, sep in (("module", "", ":"), ("device", ":", "."), ("function", ".", "")):
        end = _run_end(_NAME_RUN, text, pos)
        if end == pos:
            where = f" after '{after}'" if after else ""
            return f"expected a {kind} name{where} at column {pos + 1} but found {_what(text, pos)}"
        if end - pos > MAX_NAME:
            return f"{kind} name longer than {MAX_NAME} characters at column {pos + 1}"
        name = text[pos:end]
        names.append(name)
        pos = end
        if sep:
            if pos >= n or text[pos] != sep:
                return (f"expected '{sep}' after {kind} '{name}' at column {pos + 1}"
                        f" but found {_what(text, pos)}")
            pos += 1
    module, device, function = names
    target = f"{module}:{device}.{function}"
    if pos >= n or text[pos] != "=":
        return (f"expected '=' after function '{function}' at column {pos + 1}"
                f" but found {_what(text, pos)}")
    pos += 1
    if pos >= n or text[pos] != "(":
        return (f"expected an open parenthesis after '{target}=' at column {pos + 1}"
                f" but found {_what(text, pos)}")
    pos += 1
    params: list[str] = []
    pos = _skip_blanks(text, pos)
    if pos < n and text[pos] == ")":
        return Request(module, device, function, ()), pos + 1
    while True:
        pos = _skip_blanks(text, pos)
        start = pos
        pos = _run_end(_PARAM_RUN, text, pos)
        if pos == start:
            if pos >= n:
                return f"missing close parenthesis at end of message for '{target}'"
            if text[pos] in ",)":
                return f"empty parameter at column {pos + 1} in '{target}'"
            return (f"unexpected {_what(text, pos)} in the parameters of '{target}'"
                    f" at column {pos + 1}")
        if pos - start > MAX_PARAM:
            return f"parameter longer than {MAX_PARAM} characters at column {start + 1}"
        token = text[start:pos]
        params.append(token)
        pos = _skip_blanks(text, pos)
        if pos >= n:
            return f"missing close parenthesis at end of message for '{target}'"
        if text[pos] == ")":
            return Request(module, device, function, tuple(params)), pos + 1
        if text[pos] != ",":
            return (f"expected comma or close parenthesis after parameter '{token}'"
                    f" at column {pos + 1} but found {_what(text, pos)}")
        pos += 1


_CHAR_NAMES = {
    ",": "comma",
    "(": "open parenthesis",
    ")": "close parenthesis",
    " ": "space",
    "\t": "tab",
    "\r": "carriage return",
    "'": "quote",
}


def _what(text: str, pos: int) -> str:
    """The character at `pos` in words that survive detail sanitizing."""
    if pos >= len(text):
        return "end of message"
    ch = text[pos]
    if ch in _CHAR_NAMES:
        return _CHAR_NAMES[ch]
    if 32 < ord(ch) < 127:
        return f"'{ch}'"
    return f"byte 0x{ord(ch):02x}"


# --------------------------------------------------------------------------- formatting


def format_value(v: object) -> str:
    """One value as MCP prints it: bools 1/0, ints decimal, floats with at most 3 decimals.

    Accepts anything integral or real (numpy scalars too), so callers need not convert.
    """
    t = type(v)  # exact-type fast path: the ABC checks below cost ~1 us each on a hot path
    if t is str:
        return v  # type: ignore[return-value]
    if t is int:
        return str(v)
    if t is not float:
        if isinstance(v, str):
            return v
        if isinstance(v, bool):
            return "1" if v else "0"
        if isinstance(v, Integral):
            return str(int(v))
    if t is float or isinstance(v, Real):
        x = float(v)  # type: ignore[arg-type]
        if not math.isfinite(x):
            raise ValueError(f"MCP cannot carry a non-finite float: {x!r}")
        text = f"{x:.3f}".rstrip("0")
        if text.endswith("."):
            text += "0"
        return "0.0" if text == "-0.0" else text
    raise TypeError(f"MCP cannot carry a value of type {type(v).__name__}")


def format_response(r: Response) -> str:
    """`module:device.property=(v1,v2)`."""
    values = ",".join([format_value(v) for v in r.values])
    return f"{r.module}:{r.device}.{r.prop}=({values})"


def format_responses(rs: Iterable[Response]) -> bytes:
    """One response message: every response concatenated, then `\\n` (a bare one if none)."""
    return ("".join([format_response(r) for r in rs]) + "\n").encode("ascii")


def format_request(r: Request) -> str:
    """`module:device.function=(p1,p2)`."""
    return f"{r.module}:{r.device}.{r.function}=({','.join(r.params)})"


def format_requests(rs: Iterable[Request]) -> bytes:
    """One request message: every request concatenated, then `\\n`."""
    return ("".join([format_request(r) for r in rs]) + "\n").encode("ascii")


def parse_response_line(line: bytes) -> list[Response]:
    """Responses of one line for clients, values typed by how they look (int, float, str).

    Raises ProtocolError on anything that is not a response line.
    """
    try:
        text = bytes(line).decode("ascii")
    except UnicodeDecodeError as exc:
        raise ProtocolError(f"non-ASCII byte in response at column {exc.start + 1}") from exc
    if text.endswith("\n"):
        text = text[:-1]
    if text.endswith("\r"):
        text = text[:-1]
    out: list[Response] = []
    pos = 0
    n = len(text)
    while True:
        m = _RESPONSE.match(text, pos)
        if m is None:
            pos = _skip_blanks(text, pos)
            if pos >= n:
                return out
            snippet = text[pos:pos + 40]
            raise ProtocolError(f"not an MCP response at column {pos + 1}: {snippet!r}")
        module, device, prop, raw = m.groups()
        values = tuple(_typed(v) for v in raw.split(",")) if raw else ()
        out.append(Response(module, device, prop, values))
        pos = m.end()


def _typed(token: str) -> Value:
    token = token.strip(_BLANK)
    if _INT_FORM.match(token):
        return int(token)
    if _FLOAT_FORM.match(token):
        return float(token)
    return token


# --------------------------------------------------------------------------- framing


class LineSplitter:
    """Accumulates stream bytes and hands back complete messages, with bounded memory.

    A message longer than `max_line` bytes before its `\\n` (a trailing `\\r` not counted) is
    discarded while it arrives and reported as one TooLong marker when its `\\n` does, so the
    server still answers it once and request and response lines stay in step.
    """

    def __init__(self, max_line: int = MAX_LINE) -> None:
        if max_line < 1:
            raise ValueError("max_line must be at least 1")
        self.max_line = max_line
        self._buf = bytearray()
        self._discarding = False
        self._discarded = 0

    @property
    def pending(self) -> int:
        """Bytes held for an incomplete message (never more than max_line + 1)."""
        return len(self._buf)

    @property
    def empty(self) -> bool:
        """Nothing held: the next bytes start a new message."""
        return not self._buf and not self._discarding

    def feed(self, data: bytes) -> list[bytes | TooLong]:
        """Add received bytes; return every message they complete, in order."""
        if not isinstance(data, bytes):
            data = bytes(data)
        if not self._buf and not self._discarding and len(data) <= self.max_line:
            # The server's usual case: whole messages, nothing held. No message can be too
            # long, so a split does it (the same messages the general walk below finds).
            lines = data.split(b"\n")
            if lines[-1]:
                self._buf += lines[-1]
            return [m[:-1] if m[-1:] == b"\r" else m for m in lines[:-1]]
        out: list[bytes | TooLong] = []
        buf = self._buf
        limit = self.max_line
        n = len(data)
        start = 0
        while start < n:
            nl = data.find(b"\n", start)
            if self._discarding:
                if nl < 0:
                    self._discarded += n - start
                    break
                out.append(TooLong(self._discarded + nl - start))
                self._discarding = False
                self._discarded = 0
                start = nl + 1
                continue
            if nl < 0:
                # Keep at most limit + 1 bytes: limit of content plus a possible `\r`.
                rest = n - start
                total = len(buf) + rest
                last_cr = data[n - 1] == 13
                if total > limit + 1 or (total == limit + 1 and not last_cr):
                    self._discarding = True
                    self._discarded = total
                    buf.clear()
                else:
                    buf += data[start:]
                break
            size = len(buf) + nl - start
            # The byte before `\n` is in this chunk, or the last one buffered.
            ends_cr = data[nl - 1] == 13 if nl > start else bool(buf) and buf[-1] == 13
            if size - ends_cr > limit:
                out.append(TooLong(size))
            elif buf:
                buf += data[start:nl]
                out.append(bytes(buf[:-1]) if ends_cr else bytes(buf))
            else:
                out.append(data[start:nl - 1] if ends_cr else data[start:nl])
            buf.clear()
            start = nl + 1
        return out

    def reset(self) -> None:
        """Forget any partial message (a reconnect starts clean)."""
        self._buf.clear()
        self._discarding = False
        self._discarded = 0
