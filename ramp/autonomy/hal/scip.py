"""SCIP 2.0 (Hokuyo URG/UTM laser scanners) as pure bytes: commands out, replies in (sans-IO).

Facts used here, from Hokuyo's "Communication Protocol Specification for SCIP2.0"
(C-42-03320B), the vendor's `urg_library` (`urg_sensor.c`) and seqsense `urg_stamped`:

- A command is ASCII ending in LF: two letters, fixed-width decimal parameters, then an
  optional `;` and up to 16 "string characters" (a tag the sensor echoes back).
- A reply is the echo of the command line, a status line (two characters and a sum), any
  payload lines (each with its own sum), and an empty line: every reply ends in LF LF.
- A line's sum is the byte sum of the line, low 6 bits, plus 0x30. For `KEY:VALUE;s` lines
  (VV, PP, II) the spec leaves the `;` outside the sum, some firmware puts it inside, and
  the vendor's library accepts either, so `line_sum_ok(..., key_value=True)` does too. Scan
  data lines are checked strictly (a `;` is a legal data character there).
- Numbers are sent 6 bits per character (value + 0x30): 2 characters (12 bits, GS/MS),
  3 characters (18 bits, GD/MD ranges) or 4 characters (24 bits, timestamps). Scan data is
  one long string cut every 64 characters regardless of step boundaries.
- Status `00` is success, `99` marks an MD/MS scan, `0A`-`0L` refuse a malformed or
  ill-timed command, `10` means the laser is off (GD/GS), `50`-`98` report hardware trouble.
- The timestamp is the sensor's 24-bit millisecond counter at step 0 of the scan: it wraps
  every 2**24 ms (4 h 39 min 37 s); `TimestampUnwrapper` makes it monotonic.

The encoders validate (a bad command must never reach the sensor); the streaming decoder
never raises on bad bytes: it returns a `BadReply` that says what was wrong and where.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from math import pi

import numpy as np
import numpy.typing as npt

LF = b"\n"
DATA_LINE_CHARS = 64  # scan data is cut into lines of this many characters
MAX_TAG = 16  # "string characters" after ';'
TIMESTAMP_BITS = 24
TIMESTAMP_MODULUS = 1 << TIMESTAMP_BITS  # ms: the counter wraps after 4.66 hours
MAX_REPLY_BYTES = 1 << 16  # a full 1081-step GD reply is about 3.4 kB

#: Width in characters of one range value for each scan command.
RANGE_WIDTH = {"GD": 3, "MD": 3, "GS": 2, "MS": 2}
SCAN_COMMANDS = frozenset(RANGE_WIDTH)
STREAM_COMMANDS = frozenset({"MD", "MS"})
KEY_VALUE_COMMANDS = frozenset({"VV", "PP", "II"})

IntArray = npt.NDArray[np.int64]


class ScipError(ValueError):
    """A value that cannot be encoded, or a reply that does not say what it should."""


# -- statuses ----------------------------------------------------------------------------------
COMMON_STATUS = {
    "00": "command received without error",
    "0A": "unable to create transmission data or reply internally",
    "0B": "buffer shortage, or the same command repeated while it is being processed",
    "0C": "command with insufficient parameters",
    "0D": "undefined command (command line too long)",
    "0E": "undefined command",
    "0F": "command with insufficient parameters (2)",
    "0G": "string characters in the command exceed 16 letters",
    "0H": "string characters contain invalid letters",
    "0I": "sensor is in firmware update mode",
    "0J": "command refused (0J; see the sensor's protocol manual)",
    "0K": "command refused (0K; see the sensor's protocol manual)",
    "0L": "sensor is in an abnormal (error) state and refuses the command",
}
_SCAN_PARAM_STATUS = {
    "01": "starting step has a non-numeric value",
    "02": "end step has a non-numeric value",
    "03": "cluster count has a non-numeric value",
    "04": "end step is out of range",
    "05": "end step is smaller than the starting step",
}
COMMAND_STATUS: dict[str, dict[str, str]] = {
    "GD": {**_SCAN_PARAM_STATUS, "10": "laser is off"},
    "MD": {**_SCAN_PARAM_STATUS,
           "06": "scan interval has a non-numeric value",
           "07": "number of scans has a non-numeric value",
           "98": "resumption of measurement after confirming normal laser operation",
           "99": "scan data follows"},
    "BM": {"01": "unable to control the laser because of a laser malfunction",
           "02": "laser is already on"},
    "TM": {"01": "invalid control code",
           "02": "adjust mode on requested while it is already on",
           "03": "adjust mode off requested while it is already off",
           "04": "time requested while adjust mode is off"},
    "RB": {"01": "reboot armed: send RB again within 1 s to reboot"},
}
COMMAND_STATUS["GS"] = COMMAND_STATUS["GD"]
COMMAND_STATUS["MS"] = COMMAND_STATUS["MD"]
HARDWARE_TROUBLE = "hardware trouble (laser, motor or other malfunction)"


def is_hardware_error(status: str, command: str = "") -> bool:
    """Statuses 50-98 report a sensor hardware fault (MD/MS 98 is the recovery notice)."""
    if len(status) != 2 or not status.isdigit():
        return False
    code = int(status)
    if command in STREAM_COMMANDS and code == 98:
        return False
    return 50 <= code <= 98


def status_meaning(command: str, status: str) -> str:
    """What a status means in reply to `command` (two letters), in words."""
    specific = COMMAND_STATUS.get(command[:2], {})
    if status in specific:
        return specific[status]
    if status in COMMON_STATUS:
        return COMMON_STATUS[status]
    if status.isdigit():
        code = int(status)
        if 50 <= code <= 98:
            return HARDWARE_TROUBLE
        if 21 <= code <= 49 and command[:2] in STREAM_COMMANDS:
            return "processing stopped to verify an error"
        if code == 10:
            return "command denied in the sensor's current state"
    return f"unknown status {status!r}"


# -- sums and the 6-bit encodings --------------------------------------------------------------
def checksum(content: bytes) -> int:
    """The sum character (as a byte value) that follows `content` on a SCIP line."""
    return (sum(content) & 0x3F) + 0x30


def with_sum(content: bytes) -> bytes:
    """`content` + its sum character + LF: one reply line."""
    return content + bytes((checksum(content),)) + LF


def line_sum_ok(line: bytes, key_value: bool = False) -> bool:
    """Is the last byte of `line` (no LF) the sum of the rest?

    With `key_value`, a `KEY:VALUE;s` line also passes when the `;` was left out of the sum,
    as the spec says and the vendor's library accepts alongside the other form."""
    if len(line) < 2:
        return False
    if line[-1] == checksum(line[:-1]):
        return True
    return key_value and line[-2] == 0x3B and line[-1] == checksum(line[:-2])


def encode_int(value: int, width: int) -> bytes:
    """`value` in `width` (2, 3 or 4) characters of 6 bits each, most significant first."""
    if width not in (2, 3, 4):
        raise ScipError(f"SCIP encodes numbers in 2, 3 or 4 characters, not {width}")
    if not 0 <= value < 1 << (6 * width):
        raise ScipError(f"{value} does not fit {width} characters (0..{(1 << 6 * width) - 1})")
    return bytes(((value >> (6 * (width - 1 - i))) & 0x3F) + 0x30 for i in range(width))


def decode_int(chars: bytes) -> int:
    """The number in a 2-, 3- or 4-character field."""
    if not 1 <= len(chars) <= 4:
        raise ScipError(f"a SCIP number has 2 to 4 characters, got {len(chars)}")
    value = 0
    for c in chars:
        if not 0x30 <= c <= 0x6F:
            raise ScipError(f"{bytes((c,))!r} is not a SCIP data character (0x30-0x6F)")
        value = (value << 6) | (c - 0x30)
    return value


def encode_values(values: Sequence[int] | IntArray, width: int) -> bytes:
    """Many numbers in `width` characters each (vectorised): the body of a scan."""
    if width not in (2, 3, 4):
        raise ScipError(f"SCIP encodes numbers in 2, 3 or 4 characters, not {width}")
    arr = np.asarray(values, dtype=np.int64)
    if arr.size and (arr.min() < 0 or arr.max() >= 1 << (6 * width)):
        raise ScipError(f"values must be 0..{(1 << 6 * width) - 1} for {width}-character data")
    shifts = np.arange(width - 1, -1, -1, dtype=np.int64) * 6
    chars = ((arr[:, None] >> shifts) & 0x3F) + 0x30
    return chars.astype(np.uint8).tobytes()


def decode_values(data: bytes, width: int) -> IntArray:
    """The numbers in `data`, `width` characters each (vectorised)."""
    if width not in (2, 3, 4):
        raise ScipError(f"SCIP encodes numbers in 2, 3 or 4 characters, not {width}")
    if len(data) % width:
        raise ScipError(f"{len(data)} data characters is not a whole number of "
                        f"{width}-character values")
    return _decode_chars(np.frombuffer(data, dtype=np.uint8), width)


_WEIGHTS = {w: np.array([1 << 6 * (w - 1 - i) for i in range(w)], dtype=np.int64)
            for w in (2, 3, 4)}


def _decode_chars(raw: npt.NDArray[np.uint8], width: int) -> IntArray:
    six = raw - np.uint8(0x30)  # below 0x30 wraps round to 0xD0 and above
    if six.size and six.max() > 0x3F:
        raise ScipError("data contains characters outside 0x30-0x6F")
    out: IntArray = six.reshape(-1, width) @ _WEIGHTS[width]
    return out


def data_lines(body: bytes) -> list[bytes]:
    """Scan data cut every 64 characters, each piece with its sum and LF."""
    return [with_sum(body[i:i + DATA_LINE_CHARS]) for i in range(0, len(body), DATA_LINE_CHARS)]


# -- commands ----------------------------------------------------------------------------------
def _check_tag(tag: str) -> str:
    if not tag:
        return ""
    if len(tag) > MAX_TAG:
        raise ScipError(f"a SCIP tag has at most {MAX_TAG} characters, got {len(tag)}")
    if not (tag.isascii() and tag.isprintable()) or ";" in tag:
        raise ScipError(f"tag {tag!r} must be printable ASCII without ';'")
    return ";" + tag


def command(code: str, params: str = "", tag: str = "") -> bytes:
    """Any command line: `code` (two letters), its parameters, an optional tag."""
    if len(code) != 2 or not code.isascii() or not code.isalpha() or not code.isupper():
        raise ScipError(f"a SCIP command is two upper-case letters, not {code!r}")
    if not (params.isascii() and params.isprintable()):
        raise ScipError(f"parameters {params!r} must be printable ASCII")
    return (code + params + _check_tag(tag)).encode("ascii") + LF


def _field(name: str, value: int, digits: int, low: int = 0) -> str:
    high = 10 ** digits - 1
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise ScipError(f"{name} must be an integer {low}..{high}, got {value!r}")
    return f"{value:0{digits}d}"


def _scan_params(first: int, last: int, cluster: int) -> str:
    if isinstance(first, int) and isinstance(last, int) and last < first:
        raise ScipError(f"end step {last} is smaller than the starting step {first}")
    return (_field("starting step", first, 4) + _field("end step", last, 4)
            + _field("cluster count", cluster, 2))


def vv(tag: str = "") -> bytes:
    """Version information (vendor, product, firmware, protocol, serial)."""
    return command("VV", tag=tag)


def pp(tag: str = "") -> bytes:
    """Measurement parameters (model, DMIN/DMAX, ARES, AMIN/AMAX/AFRT, SCAN)."""
    return command("PP", tag=tag)


def ii(tag: str = "") -> bytes:
    """Status information (laser, motor speed, mode, time, sensor state)."""
    return command("II", tag=tag)


def bm(tag: str = "") -> bytes:
    """Laser on (needed before GD/GS; MD/MS switch it on by themselves)."""
    return command("BM", tag=tag)


def qt(tag: str = "") -> bytes:
    """Laser off; stops any MD/MS stream."""
    return command("QT", tag=tag)


def rs(tag: str = "") -> bytes:
    """Reset settings: laser off, default speed, the timestamp counter back to zero."""
    return command("RS", tag=tag)


def rb(tag: str = "") -> bytes:
    """Reboot: the sensor reboots on the second RB within one second."""
    return command("RB", tag=tag)


def tm(control: int, tag: str = "") -> bytes:
    """Time adjust: 0 enters adjust mode, 1 asks the time, 2 leaves adjust mode."""
    if control not in (0, 1, 2):
        raise ScipError(f"TM control code is 0, 1 or 2, not {control!r}")
    return command("TM", str(control), tag)


def gd(first: int = 0, last: int = 1080, cluster: int = 1, tag: str = "") -> bytes:
    """One scan, 3-character ranges (to 262 m): `GD0000108001`."""
    return command("GD", _scan_params(first, last, cluster), tag)


def gs(first: int = 0, last: int = 1080, cluster: int = 1, tag: str = "") -> bytes:
    """One scan, 2-character ranges (to 4.095 m)."""
    return command("GS", _scan_params(first, last, cluster), tag)


def md(first: int = 0, last: int = 1080, cluster: int = 1, interval: int = 0, scans: int = 0,
       tag: str = "") -> bytes:
    """A stream of scans, 3-character ranges: every `interval + 1`-th scan, `scans` of
    them (0 = until QT): `MD0000108001000`."""
    return command("MD", _scan_params(first, last, cluster) + _field("scan interval", interval, 1)
                   + _field("number of scans", scans, 2), tag)


def ms(first: int = 0, last: int = 1080, cluster: int = 1, interval: int = 0, scans: int = 0,
       tag: str = "") -> bytes:
    """A stream of scans, 2-character ranges."""
    return command("MS", _scan_params(first, last, cluster) + _field("scan interval", interval, 1)
                   + _field("number of scans", scans, 2), tag)


# -- replies -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class ScanRequest:
    """The parameters of a GD/GS/MD/MS command, read back from its echo."""

    command: str
    first: int
    last: int
    cluster: int
    interval: int = 0
    scans: int = 0  # MD/MS: number asked for, or in a scan's echo the scans still to come
    tag: str = ""

    @property
    def width(self) -> int:
        return RANGE_WIDTH[self.command]

    @property
    def count(self) -> int:
        """How many values one scan carries: one per cluster of steps."""
        return (self.last - self.first) // max(1, self.cluster) + 1


def parse_scan_echo(echo: str) -> ScanRequest:
    """`MD0000108001099;tag` -> its fields; ScipError when the echo is not a scan command."""
    body, _, tag = echo.partition(";")
    code = body[:2]
    if code not in SCAN_COMMANDS:
        raise ScipError(f"{echo!r} is not a GD/GS/MD/MS command")
    size = 15 if code in STREAM_COMMANDS else 12
    if len(body) != size or not body[2:].isdigit():
        raise ScipError(f"{echo!r}: a {code} command has {size - 2} digits of parameters")
    req = ScanRequest(code, int(body[2:6]), int(body[6:10]), int(body[10:12]), tag=tag)
    if req.last < req.first:
        raise ScipError(f"{echo!r}: end step is smaller than the starting step")
    if code in STREAM_COMMANDS:
        req = ScanRequest(code, req.first, req.last, req.cluster, int(body[12]), int(body[13:15]),
                          tag)
    return req


@dataclass(frozen=True, eq=False)
class Reply:
    """One whole, sum-checked reply."""

    echo: str
    status: str
    lines: tuple[str, ...] = ()  # payload lines without sums (KEY:VALUE without the ';')
    request: ScanRequest | None = None  # GD/GS/MD/MS: the echo's parameters
    timestamp_ms: int | None = None  # scans and TM1: the sensor's 24-bit ms counter
    values: IntArray | None = None  # scans: one range (mm) or error code per cluster
    raw: bytes = field(default=b"", repr=False)

    @property
    def command(self) -> str:
        return self.echo[:2]

    @property
    def tag(self) -> str:
        return self.echo.partition(";")[2]

    @property
    def is_scan(self) -> bool:
        """True when the reply carries scan data (GD/GS 00, MD/MS 99)."""
        return self.values is not None

    @property
    def meaning(self) -> str:
        return status_meaning(self.command, self.status)

    @property
    def hardware_error(self) -> bool:
        return is_hardware_error(self.status, self.command)

    def key_values(self) -> dict[str, str]:
        """VV/PP/II payload as a dict (`KEY:VALUE` lines)."""
        out: dict[str, str] = {}
        for line in self.lines:
            key, sep, value = line.partition(":")
            if sep:
                out[key] = value
        return out


@dataclass(frozen=True)
class BadReply:
    """Bytes that do not make a valid reply, and why; the decoder has moved past them."""

    kind: str  # "checksum", "truncated", "garbled" or "overflow"
    reason: str
    echo: str = ""  # the first line, when it was readable
    raw: bytes = field(default=b"", repr=False)
    line: int = -1  # 0-based line of the problem (0 = echo), -1 when not about one line

    def __str__(self) -> str:
        where = f" (line {self.line})" if self.line >= 0 else ""
        what = f" in reply to {self.echo!r}" if self.echo else ""
        return f"{self.kind}{what}{where}: {self.reason}"


Decoded = Reply | BadReply


def _text(line: bytes) -> str | None:
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        return None
    return text if text.isprintable() else None


def decode_reply(block: bytes) -> Decoded:
    """One reply without its final empty line (`echo LF status LF ... LF`, or no LF at end)."""
    raw = block
    lines = block.rstrip(LF).split(LF) if block else []
    echo = _text(lines[0]) if lines else None
    if not echo or len(echo) < 2:
        return BadReply("garbled", "the first line is not a printable command echo", "", raw, 0)
    if len(lines) < 2:
        return BadReply("truncated", "no status line", echo, raw, 1)
    status_line = lines[1]
    if len(status_line) != 3:
        return BadReply("garbled", f"status line {status_line!r} is not 2 characters and a sum",
                        echo, raw, 1)
    if not line_sum_ok(status_line):
        return BadReply("checksum", f"status line {status_line!r} fails its sum", echo, raw, 1)
    status = status_line[:2].decode("ascii", "replace")
    code = echo[:2]
    payload = lines[2:]
    if code in SCAN_COMMANDS and status in ("00", "99"):
        return _decode_scan(echo, status, payload, raw)
    if code == "TM" and echo[2:3] == "1" and status == "00":
        return _decode_time(echo, payload, raw)
    key_value = code in KEY_VALUE_COMMANDS
    texts: list[str] = []
    for i, line in enumerate(payload, start=2):
        if not line_sum_ok(line, key_value=key_value):
            return BadReply("checksum", f"line {line!r} fails its sum", echo, raw, i)
        text = _text(line[:-1])
        if text is None:
            return BadReply("garbled", f"line {line!r} is not printable ASCII", echo, raw, i)
        if key_value and text.endswith(";"):
            text = text[:-1]
        texts.append(text)
    if key_value and status == "00":
        for i, text in enumerate(texts, start=2):
            if ":" not in text:
                return BadReply("garbled", f"line {text!r} is not KEY:VALUE", echo, raw, i)
    return Reply(echo, status, tuple(texts), raw=raw)


def _decode_time(echo: str, payload: list[bytes], raw: bytes) -> Decoded:
    if not payload:
        return BadReply("truncated", "TM1 reply without its time line", echo, raw, 2)
    line = payload[0]
    if len(line) != 5:
        return BadReply("garbled", f"time line {line!r} is not 4 characters and a sum",
                        echo, raw, 2)
    if not line_sum_ok(line):
        return BadReply("checksum", f"time line {line!r} fails its sum", echo, raw, 2)
    try:
        ms_value = decode_int(line[:4])
    except ScipError as exc:
        return BadReply("garbled", str(exc), echo, raw, 2)
    return Reply(echo, "00", timestamp_ms=ms_value, raw=raw)


def _decode_scan(echo: str, status: str, payload: list[bytes], raw: bytes) -> Decoded:
    try:
        req = parse_scan_echo(echo)
    except ScipError as exc:
        return BadReply("garbled", str(exc), echo, raw, 0)
    if req.command in STREAM_COMMANDS and status == "00":  # the stream's acknowledgement
        if payload:
            return BadReply("garbled", "MD/MS acknowledgement carries data", echo, raw, 2)
        return Reply(echo, status, request=req, raw=raw)
    if (req.command in STREAM_COMMANDS) != (status == "99"):
        return BadReply("garbled", f"status {status} cannot carry {req.command} data",
                        echo, raw, 1)
    if not payload:
        return BadReply("truncated", "scan reply without its timestamp", echo, raw, 2)
    stamp = payload[0]
    if len(stamp) != 5:
        return BadReply("garbled", f"timestamp line {stamp!r} is not 4 characters and a sum",
                        echo, raw, 2)
    if not line_sum_ok(stamp):
        return BadReply("checksum", f"timestamp line {stamp!r} fails its sum", echo, raw, 2)
    chars = _data_chars(payload[1:])
    if isinstance(chars, tuple):
        kind, reason, line = chars
        return BadReply(kind, reason, echo, raw, line)
    expected = req.count * req.width
    if chars.size != expected:
        kind = "truncated" if chars.size < expected else "garbled"
        return BadReply(kind, f"{chars.size} data characters, {expected} expected for "
                        f"{req.count} steps of {req.width} characters", echo, raw, -1)
    try:
        stamp_ms = decode_int(stamp[:4])
        values = _decode_chars(chars, req.width)
    except ScipError as exc:
        return BadReply("garbled", str(exc), echo, raw, -1)
    return Reply(echo, status, request=req, timestamp_ms=stamp_ms, values=values, raw=raw)


def _data_chars(lines: list[bytes]) -> npt.NDArray[np.uint8] | tuple[str, str, int]:
    """The data characters of scan lines (each 64 but the last), sums checked all at once;
    or (kind, reason, line number) for the first bad line."""
    if not lines:
        return np.zeros(0, dtype=np.uint8)
    full, last = lines[:-1], lines[-1]
    width = DATA_LINE_CHARS + 1
    joined = b"".join(full)
    if len(joined) != len(full) * width:
        i = next(i for i, line in enumerate(full) if len(line) != width)
        return ("garbled", f"data line of {len(full[i]) - 1} characters (lines are cut every "
                f"{DATA_LINE_CHARS})", i + 3)
    if not 2 <= len(last) <= width:
        return ("garbled", f"data line of {len(last) - 1} characters (lines are cut every "
                f"{DATA_LINE_CHARS})", len(lines) + 2)
    grid = np.frombuffer(joined, dtype=np.uint8).reshape(len(full), width)
    sums = (grid[:, :DATA_LINE_CHARS].sum(axis=1, dtype=np.int64) & 0x3F) + 0x30
    wrong = np.flatnonzero(sums != grid[:, DATA_LINE_CHARS])
    if wrong.size:
        i = int(wrong[0])
        return ("checksum", f"data line {full[i]!r} fails its sum", i + 3)
    if not line_sum_ok(last):
        return ("checksum", f"data line {last!r} fails its sum", len(lines) + 2)
    tail = np.frombuffer(last, dtype=np.uint8)[:-1]
    return np.concatenate((grid[:, :DATA_LINE_CHARS].ravel(), tail))


class ScipDecoder:
    """Streaming decoder: `feed(bytes)` returns every reply completed by those bytes.

    Replies end at an empty line (LF LF); a reply that fails is returned as a `BadReply` and
    the decoder carries on at the next one. Bytes that never reach an empty line within
    `max_reply` are dropped as one "overflow" `BadReply`.
    """

    def __init__(self, max_reply: int = MAX_REPLY_BYTES) -> None:
        self.max_reply = max_reply
        self._buf = bytearray()
        self._scan_from = 0

    @property
    def pending(self) -> int:
        """Bytes received that do not yet make a whole reply."""
        return len(self._buf)

    def reset(self) -> None:
        """Forget partial input (after a reconnect)."""
        self._buf.clear()
        self._scan_from = 0

    def feed(self, data: bytes) -> list[Decoded]:
        self._buf += data
        out: list[Decoded] = []
        start = 0
        buf = self._buf
        while True:
            end = buf.find(b"\n\n", max(start, self._scan_from - 1))
            if end < 0:
                break
            block = bytes(buf[start:end + 1])
            start = end + 2
            self._scan_from = start
            if block.strip(LF):
                out.append(decode_reply(block.lstrip(LF)))
        if start:
            del buf[:start]
            self._scan_from = 0
        self._scan_from = max(self._scan_from, len(buf))
        if len(buf) > self.max_reply:
            head = _text(bytes(buf[:buf.find(LF)])) if LF in buf else None
            out.append(BadReply("overflow", f"{len(buf)} bytes without the empty line that "
                                "ends a reply", head or "", bytes(buf[:256]), -1))
            self.reset()
        return out

    def close(self) -> BadReply | None:
        """End of input: a reply cut short by a closed connection, if any."""
        if not self._buf.strip(LF):
            self.reset()
            return None
        block = bytes(self._buf)
        self.reset()
        head = _text(block.split(LF, 1)[0]) or ""
        return BadReply("truncated", f"input ended after {len(block)} bytes of a reply", head,
                        block, -1)


# -- reply encoders (for emulators, tests and benchmarks) --------------------------------------
def encode_reply(echo: str | bytes, status: str, lines: Iterable[bytes] = ()) -> bytes:
    """A whole reply: echo, status with sum, the given (already summed) lines, empty line."""
    echo_b = echo.encode("ascii") if isinstance(echo, str) else echo
    if len(status) != 2:
        raise ScipError(f"a status is two characters, not {status!r}")
    return echo_b.rstrip(LF) + LF + with_sum(status.encode("ascii")) + b"".join(lines) + LF


def key_value_lines(pairs: Mapping[str, str] | Iterable[tuple[str, str]],
                    semicolon_in_sum: bool = False) -> list[bytes]:
    """`KEY:VALUE;s` lines; the `;` is outside the sum unless `semicolon_in_sum`."""
    items = pairs.items() if isinstance(pairs, Mapping) else pairs
    out = []
    for key, value in items:
        content = f"{key}:{value}".encode("ascii")
        s = checksum(content + b";") if semicolon_in_sum else checksum(content)
        out.append(content + b";" + bytes((s,)) + LF)
    return out


def encode_scan_reply(echo: str, status: str, timestamp_ms: int,
                      values: Sequence[int] | IntArray, width: int = 3) -> bytes:
    """A GD/GS (status 00) or MD/MS (status 99) scan reply with its data cut every 64."""
    stamp = with_sum(encode_int(timestamp_ms % TIMESTAMP_MODULUS, 4))
    return encode_reply(echo, status, [stamp, *data_lines(encode_values(values, width))])


# -- what the replies say ----------------------------------------------------------------------
@dataclass(frozen=True)
class VersionInfo:
    """VV: who made the sensor and what it runs."""

    vendor: str
    product: str
    firmware: str
    protocol: str
    serial: str


def parse_version(reply: Reply) -> VersionInfo:
    _expect_ok(reply, "VV")
    kv = reply.key_values()
    return VersionInfo(kv.get("VEND", ""), kv.get("PROD", ""), kv.get("FIRM", ""),
                       kv.get("PROT", ""), kv.get("SERI", ""))


@dataclass(frozen=True)
class SensorParams:
    """PP: the sensor's geometry. Step s points at (s - AFRT) * 2π / ARES rad, counter-
    clockwise seen from above, 0 straight ahead; ranges are valid from DMIN to DMAX mm."""

    model: str
    dmin_mm: int
    dmax_mm: int
    ares: int  # steps per full turn
    amin: int  # first measurable step
    amax: int  # last measurable step
    afrt: int  # the step straight ahead
    scan_rpm: int

    @property
    def step_rad(self) -> float:
        return 2 * pi / self.ares

    @property
    def scan_period_s(self) -> float:
        return 60.0 / self.scan_rpm

    @property
    def steps(self) -> int:
        return self.amax - self.amin + 1

    def angle(self, step: float) -> float:
        """Bearing of `step` in radians, counter-clockwise from straight ahead."""
        return (step - self.afrt) * self.step_rad

    def check(self) -> None:
        """ScipError unless the numbers make a usable scanner."""
        problems = []
        if not 0 < self.dmin_mm < self.dmax_mm:
            problems.append(f"DMIN {self.dmin_mm} / DMAX {self.dmax_mm}")
        if self.ares <= 0 or not 0 <= self.amin <= self.afrt <= self.amax < self.ares:
            problems.append(f"ARES {self.ares} / AMIN {self.amin} / AFRT {self.afrt} / "
                            f"AMAX {self.amax}")
        if self.scan_rpm <= 0:
            problems.append(f"SCAN {self.scan_rpm}")
        if problems:
            raise ScipError("PP parameters make no sense: " + ", ".join(problems))


PP_KEYS = ("MODL", "DMIN", "DMAX", "ARES", "AMIN", "AMAX", "AFRT", "SCAN")


def parse_params(reply: Reply) -> SensorParams:
    _expect_ok(reply, "PP")
    kv = reply.key_values()
    missing = [k for k in PP_KEYS if k not in kv]
    if missing:
        raise ScipError(f"PP reply lacks {', '.join(missing)}")
    numbers: dict[str, int] = {}
    for key in PP_KEYS[1:]:
        try:
            numbers[key] = int(kv[key].strip())
        except ValueError:
            raise ScipError(f"PP {key}:{kv[key]!r} is not a number") from None
    params = SensorParams(kv["MODL"], numbers["DMIN"], numbers["DMAX"], numbers["ARES"],
                          numbers["AMIN"], numbers["AMAX"], numbers["AFRT"], numbers["SCAN"])
    params.check()
    return params


@dataclass(frozen=True)
class StatusInfo:
    """II: the sensor's state as it reports it."""

    fields: dict[str, str]

    @property
    def laser_on(self) -> bool:
        return self.fields.get("LASR", "").strip().upper().startswith("ON")

    @property
    def time_ms(self) -> int | None:
        """TIME: 4 SCIP characters on most models, 6 hex digits on some."""
        text = self.fields.get("TIME", "").strip()
        try:
            if len(text) == 4:
                return decode_int(text.encode("ascii"))
            if len(text) == 6:
                return int(text, 16)
        except (ScipError, ValueError):
            return None
        return None

    @property
    def stat(self) -> str:
        return self.fields.get("STAT", "")


def parse_status(reply: Reply) -> StatusInfo:
    _expect_ok(reply, "II")
    return StatusInfo(reply.key_values())


def _expect_ok(reply: Reply, code: str) -> None:
    if reply.command != code:
        raise ScipError(f"expected a {code} reply, got {reply.echo!r}")
    if reply.status != "00":
        raise ScipError(f"{code} answered {reply.status}: {reply.meaning}")


# -- time --------------------------------------------------------------------------------------
def unwrap_delta(previous_raw: int, raw: int) -> int:
    """Milliseconds from `previous_raw` to `raw` on the 24-bit counter, in -2**23..2**23."""
    delta = (raw - previous_raw) % TIMESTAMP_MODULUS
    return delta - TIMESTAMP_MODULUS if delta >= TIMESTAMP_MODULUS // 2 else delta


class TimestampUnwrapper:
    """Turns the sensor's wrapping 24-bit ms counter into a monotonic count of ms.

    Consecutive stamps are assumed less than 2**23 ms (2.3 h) apart, so a step backwards
    (a sensor reset) shows as going backwards rather than as a 4.66-hour jump forwards.
    """

    def __init__(self) -> None:
        self._raw: int | None = None
        self._total = 0

    def reset(self) -> None:
        self._raw = None
        self._total = 0

    def unwrap(self, raw: int) -> int:
        if not 0 <= raw < TIMESTAMP_MODULUS:
            raise ScipError(f"timestamp {raw} is outside the 24-bit counter")
        if self._raw is None:
            self._total = raw
        else:
            self._total += unwrap_delta(self._raw, raw)
        self._raw = raw
        return self._total
