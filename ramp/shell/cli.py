"""`ramp-shell [HOST:PORT]`: an interactive MCP client for poking at a robot (SPEC section 5).

It is a client process and blocks by design; it reaches the robot only through MCP. Two
connections keep the safety rule simple: the main one carries only what the user typed and
`hold`'s heartbeats, so the shell never feeds the watchdog on its own; a second, read-only
one carries `describe`, the module check and `watch` polls, which the supervisor never counts
as feeding (they come from a client that is not the feeder).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import select
import signal
import socket
import ssl
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from types import FrameType
from typing import TextIO

from prompt_toolkit.history import FileHistory, History, InMemoryHistory

from ramp.common.endpoint import add_tls_arguments, context_for, split_scheme
from ramp.common.hostport import format_hostport
from ramp.errors import ProtocolError
from ramp.mcp.client import DEFAULT_PORT, McpClient, parse_address
from ramp.mcp.messages import Request, Response
from ramp.mcp.protocol import format_requests, parse_message, parse_response_line
from ramp.shell.complete import complete, param_hint, split_command
from ramp.shell.render import (
    READ_FUNCTIONS,
    Catalog,
    build_catalog,
    error_text,
    has_errors,
    modules_listed,
    render_help,
    render_responses,
)

#: Seconds a request may take before the shell gives up on the line (and on the connection:
#: a late answer would pair with the next request).
DEFAULT_TIMEOUT = 2.0
MAX_TIMEOUT_S = 3600.0  # an hour: beyond it (1e308) the socket layer overflows
#: Modules that answer describe without being listed by `robot:robot.describe` (SPEC 12's
#: `sim`, present only under `--sim`).
OPTIONAL_MODULES = ("sim",)
#: At most this often does the shell ask `robot.modules` after a typed line.
MODULE_CHECK_PERIOD = 1.0
MAX_WATCH_HZ = 50.0
#: Slowest watch: one poll every 100 s. Slower rates meant waits no clock takes (`watch … 1e-10`
#: was an OverflowError traceback from select, which ended the interactive shell too).
MIN_WATCH_HZ = 0.01
MAX_HOLD_S = 3600.0

EXIT_OK, EXIT_ERROR, EXIT_CONNECTION = 0, 1, 2

_CLEAR = "\x1b[H\x1b[J"


class ConnectionLost(Exception):
    """The robot cannot be reached: refused, closed, timed out or answered `busy`."""


class Quit(Exception):
    """The user asked to leave."""


class UsageError(Exception):
    """A shell command typed wrong; the message says how to type it."""


# --------------------------------------------------------------------------- pure helpers


def history_path(env: dict[str, str] | os._Environ[str] | None = None) -> Path:
    """`$XDG_DATA_HOME/ramp/shell_history`, or `~/.local/share/ramp/shell_history`."""
    env = os.environ if env is None else env
    base = env.get("XDG_DATA_HOME") or ""
    root = Path(base) if base else Path(env.get("HOME") or Path.home()) / ".local" / "share"
    return root / "ramp" / "shell_history"


def parse_requests(text: str) -> list[Request]:
    """The requests of one typed message, or UsageError with the parser's own words."""
    parsed = parse_message(text.encode("ascii", "replace"))
    if parsed.syntax_error is not None:
        raise UsageError(error_text(parsed.syntax_error))
    return list(parsed.requests)


def split_trailing_number(rest: str, what: str, lo: float, hi: float, *, lo_open: bool = True
                          ) -> tuple[str, float | None]:
    """`base:base.get=() 5` -> (`base:base.get=()`, 5.0); the number is optional. It must be
    above `lo` (at least `lo` when not `lo_open`) and at most `hi`."""
    parts = rest.rsplit(None, 1)
    if len(parts) == 2 and parts[0].rstrip().endswith(")"):
        try:
            value = float(parts[1])
        except ValueError:
            return rest.strip(), None
        above = lo < value if lo_open else lo <= value
        if not math.isfinite(value) or not above or not value <= hi:
            raise UsageError(f"{what} must be in {lo:g} {'<' if lo_open else '<='} {what} <= "
                             f"{hi:g}, not {parts[1]}")
        return parts[0].strip(), value
    return rest.strip(), None


def stop_message(requests: Iterable[Request], known: Iterable[str]) -> str:
    """One message stopping every module the requests named (`robot` -> `robot.stop`)."""
    known_set = set(known)
    modules: dict[str, None] = {}
    for r in requests:
        if r.module in known_set:
            modules.setdefault(r.module)
    return format_requests(Request(m, m, "stop") for m in modules).decode().rstrip("\n")


def accepted_motion(requests: Iterable[Request], responses: Iterable[Response],
                    catalog: Catalog | None = None) -> list[Request]:
    """The requests that change something (not reads, as `catalog` says, or by name) that
    the robot did not refuse (errors echo module and device).

    `hold` stops only these: a refused request (say `not_owner`) must not end with a stop
    that halts another client's motion.
    """
    refused = {(r.module, r.device) for r in responses if r.prop == "error"}
    return [r for r in requests
            if not _is_read(r, catalog) and (r.module, r.device) not in refused]


def _is_read(r: Request, catalog: Catalog | None) -> bool:
    """A read, as describe said (`kind`), or by its name for a robot that does not say."""
    if catalog is None:
        return r.function in READ_FUNCTIONS
    return catalog.is_read(r.module, r.device, r.function)


def watchdog_timeout(rows: Iterable[Response]) -> float | None:
    for r in rows:
        if (r.module, r.device, r.prop) == ("robot", "watchdog", "timeout") and r.values:
            v = r.values[0]
            if isinstance(v, int | float):
                return float(v)
    return None


def interlocks_active(rows: Iterable[Response]) -> list[str] | None:
    """The active interlocks in `robot.get`'s rows ([] for `none`), None without the row."""
    for r in rows:
        if (r.module, r.device, r.prop) == ("robot", "interlock", "active"):
            return [str(v) for v in r.values if v != "none"]
    return None


def heartbeat_period(timeout: float | None) -> float:
    """A quarter of the watchdog timeout, so a late heartbeat or two never trips it."""
    t = 1.0 if timeout is None else timeout
    return min(0.25, max(0.02, t / 4))


# --------------------------------------------------------------------------- Ctrl-C


class Interrupt:
    """Ctrl-C as a flag while a command runs, so it never tears a request from its answer.

    The handler only sets `hit`; the signal's wakeup byte ends a wait at once. Outside the
    main thread (where signals cannot be caught) it is a plain timed wait.
    """

    def __init__(self) -> None:
        self.hit = False
        self._r: socket.socket | None = None
        self._w: socket.socket | None = None
        self._old_handler: Callable[[int, FrameType | None], object] | int | None = None
        self._old_fd = -1
        self._installed = False

    def __enter__(self) -> Interrupt:
        try:
            self._old_handler = signal.signal(signal.SIGINT, self._on_signal)
        except ValueError:  # not the main thread
            return self
        self._installed = True
        self._r, self._w = socket.socketpair()
        self._r.setblocking(False)
        self._w.setblocking(False)
        self._old_fd = signal.set_wakeup_fd(self._w.fileno(), warn_on_full_buffer=False)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._installed:
            signal.set_wakeup_fd(self._old_fd)
            signal.signal(signal.SIGINT, self._old_handler)
            for s in (self._r, self._w):
                if s is not None:
                    s.close()
            self._installed = False

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        self.hit = True

    def wait(self, seconds: float) -> None:
        """Wait up to `seconds`, or until Ctrl-C."""
        if self.hit or seconds <= 0:
            return
        fds = [self._r] if self._r is not None else []
        readable, _, _ = select.select(fds, [], [], seconds)
        if readable and self._r is not None:
            with contextlib.suppress(BlockingIOError):
                self._r.recv(64)


# --------------------------------------------------------------------------- the shell


class Shell:
    """One session with one robot: connections, catalog, and the commands a line can be."""

    def __init__(self, host: str, port: int, out: TextIO, *, color: bool = False,
                 timeout: float = DEFAULT_TIMEOUT, raw: bool = False,
                 clock: Callable[[], float] = time.monotonic,
                 ssl_context: ssl.SSLContext | None = None) -> None:
        self.host, self.port, self.out = host, port, out
        #: `mcps://` (SPEC 13): every connection of this shell runs inside mutual TLS.
        self.ssl_context = ssl_context
        self.color, self.timeout, self.raw, self.clock = color, timeout, raw, clock
        self.main: McpClient | None = None
        self.monitor: McpClient | None = None
        self.catalog = Catalog(modules=["robot"])
        self.attached: list[str] | None = None
        self._last_check = -math.inf
        self.interactive = False

    # -- output -------------------------------------------------------------------------------
    def say(self, text: str = "") -> None:
        self.out.write(text + "\n")
        self.out.flush()

    def show(self, responses: Sequence[Response], raw_line: bytes | None = None) -> None:
        if self.raw and raw_line is not None:
            self.say(raw_line.decode("ascii", "replace"))
        else:
            self.say(render_responses(responses, self.catalog, color=self.color))

    # -- connections --------------------------------------------------------------------------
    @property
    def address(self) -> str:
        scheme = "mcps://" if self.ssl_context is not None else ""
        return f"{scheme}{format_hostport(self.host, self.port)}"

    def _open(self) -> McpClient:
        try:
            return McpClient(self.host, self.port, timeout=self.timeout,
                             ssl_context=self.ssl_context)
        except ssl.SSLCertVerificationError as exc:
            raise ConnectionLost(f"cannot connect to {self.address}: the robot's certificate "
                                 f"is not trusted ({exc.verify_message}): is --ca the robot's "
                                 "CA, and the host a name its certificate was made for?"
                                 ) from exc
        except OSError as exc:
            reason = exc.strerror or str(exc) or type(exc).__name__
            raise ConnectionLost(f"cannot connect to {self.address}: {reason}") from exc

    def connect(self, *, describe: bool = True, monitor: bool = False) -> None:
        """Open the main connection (and the read-only one) and learn what the robot offers."""
        self.close()
        self.main = self._open()
        if monitor:
            self.monitor = self._open()
        if describe:
            self.describe()

    def close(self) -> None:
        for c in (self.main, self.monitor):
            if c is not None:
                c.close()
        self.main = self.monitor = None

    def _reader(self) -> McpClient:
        """The read-only connection, opened on first use."""
        if self.monitor is None or self.monitor.closed:
            self.monitor = self._open()
        return self.monitor

    def _ask(self, client: McpClient, message: str) -> tuple[list[Response], bytes]:
        """Send one message, return its responses and raw line; failures -> ConnectionLost."""
        try:
            client.send(message)
            line = client.recv_line()
            responses = parse_response_line(line)
        except (OSError, ProtocolError) as exc:  # refused, reset, closed, timed out, garbled
            client.close()
            raise ConnectionLost(str(exc)) from exc
        for r in responses:
            if r.prop == "error" and r.values and r.values[0] == "busy":
                client.close()
                raise ConnectionLost(f"{self.address} is busy: {error_text(r)}")
        return responses, line

    def ask_main(self, message: str) -> tuple[list[Response], bytes]:
        if self.main is None or self.main.closed:
            raise ConnectionLost(f"not connected to {self.address}")
        try:
            return self._ask(self.main, message)
        except ConnectionLost:
            self.main = None
            raise

    def ask_reader(self, message: str, *, separate: bool = False) -> list[Response]:
        """A read on the second connection.

        In one-shot mode a read the user asked for goes on the main connection (one socket
        less); `separate` reads, repeated without the user (watch), never do: on the main
        connection they would feed the watchdog of a motion this shell started.
        """
        if (not separate and not self.interactive and self.monitor is None
                and self.main is not None):
            return self.ask_main(message)[0]
        try:
            return self._ask(self._reader(), message)[0]
        except ConnectionLost:
            self.monitor = None
            raise

    def describe(self) -> None:
        """Build the catalog from `describe`; modules that cannot describe are noted."""
        robot_rows = self.ask_reader("robot:robot.describe=()")
        names = [r.values[0] for r in robot_rows
                 if (r.module, r.device, r.prop) == ("robot", "robot", "module") and r.values]
        module_rows: dict[str, list[Response]] = {}
        # `sim` (SPEC 12, under --sim) is not a robot module: robot.describe does not list it,
        # but it describes itself like one. Asked too; kept only where it answers.
        extra = [m for m in OPTIONAL_MODULES if m not in names]
        # One message for all modules: an error for one does not stop the others.
        message = "".join(f"{n}:{n}.describe=()" for n in [*names, *extra])
        rows = self.ask_reader(message)
        for n in names:
            module_rows[str(n)] = [r for r in rows if r.module == n]
        for n in extra:
            mine = [r for r in rows if r.module == n]
            if mine and not any(r.prop == "error" for r in mine):
                module_rows[n] = mine
        old, self.catalog = self.catalog, build_catalog(robot_rows, module_rows)
        for name in self.catalog.problems:
            # A module in fault cannot describe itself; keep completing what it offered.
            if not self.catalog.functions.get(name) and old.functions.get(name):
                self.catalog.functions[name] = old.functions[name]
                self.catalog.properties[name] = old.properties.get(name, [])
        listed = modules_listed(self.ask_reader("robot:robot.modules=()"))
        self.attached = listed
        self._last_check = self.clock()

    def check_modules(self, responses: Sequence[Response] = ()) -> None:
        """Re-describe when `robot.modules` changed (seen in an answer, or asked now and then)."""
        listed = modules_listed(responses)
        suspicious = any(r.prop == "error" and r.values
                         and r.values[0] in ("unknown_module", "not_attached", "fault")
                         for r in responses)
        if listed is None and (suspicious or self.clock() - self._last_check
                               >= MODULE_CHECK_PERIOD):
            listed = modules_listed(self.ask_reader("robot:robot.modules=()"))
            self._last_check = self.clock()
        if listed is not None and listed != self.attached:
            self.describe()
            shown = ", ".join(self.attached or []) or "none"
            self.say(f"(modules changed: now {shown}; completion updated)")

    # -- one typed line -----------------------------------------------------------------------
    def run_line(self, line: str) -> int:
        """Run one typed line: a shell command or one MCP message. Returns an exit status."""
        stripped = line.strip()
        word = stripped.split(None, 1)[0] if stripped else ""
        if word in ("quit", "exit") and stripped == word:
            raise Quit
        if word == "help" and stripped == word:
            return self.cmd_help()
        if word == "reload" and stripped == word:
            self.describe()
            self.say(f"described: {', '.join(self.catalog.modules)}")
            return EXIT_OK
        command, rest = split_command(line)
        try:
            if word in ("help", "reload", "quit", "exit"):
                raise UsageError(f"{word} takes no arguments")
            if command == "watch":
                return self.cmd_watch(rest)
            if command == "hold":
                return self.cmd_hold(rest)
            if word in ("watch", "hold"):
                raise UsageError(f"usage: {word} REQUEST "
                                 f"[{'HZ' if word == 'watch' else 'SECONDS'}]")
            if word and ":" not in word and ":" not in stripped:
                raise UsageError(f"unknown command {word!r}; type help")
        except UsageError as exc:
            self.say(str(exc))
            return EXIT_ERROR
        return self.send_line(stripped)

    def send_line(self, text: str) -> int:
        """One MCP message as typed; an empty one is a heartbeat and prints nothing."""
        if not text.isascii():
            self.say("MCP is ASCII only")
            return EXIT_ERROR
        responses, raw = self.ask_main(text)
        if text or self.raw:
            self.show(responses, raw)
        if any(r.prop == "error" and r.values and r.values[0] == "interlocked"
               for r in responses):
            self.explain_interlocks()
        if self.interactive:
            self.check_modules(responses)
        return EXIT_ERROR if has_errors(responses) else EXIT_OK

    def explain_interlocks(self) -> None:
        """After a request refused by an interlock: which rules are active now (SPEC 11)."""
        try:
            rows = self.ask_reader("robot:robot.get=()")
        except ConnectionLost:
            return
        names = interlocks_active(rows)
        if names is None:
            return
        shown = ", ".join(names) if names else "none any more"
        text = (f"active interlocks: {shown} (robot:robot.get=() shows them; a latched one "
                "is cleared with robot:interlock.reset=(NAME) once its condition has cleared)")
        if self.raw:
            # --raw prints the robot's answers and nothing else: a script reads stdout as
            # response lines, so the explanation goes to stderr.
            print(text, file=sys.stderr, flush=True)
        else:
            self.say(text)

    def cmd_help(self) -> int:
        timeout = None
        with contextlib.suppress(ConnectionLost):
            timeout = watchdog_timeout(self.ask_reader("robot:robot.get=()"))
        self.say(render_help(self.catalog, watchdog_timeout=timeout, color=self.color))
        return EXIT_OK

    def cmd_watch(self, rest: str) -> int:
        """Re-poll a read at HZ over the read-only connection until Ctrl-C."""
        text, hz = split_trailing_number(rest, "HZ", MIN_WATCH_HZ, MAX_WATCH_HZ, lo_open=False)
        if not text:
            raise UsageError("usage: watch REQUEST [HZ]")
        requests = parse_requests(text)
        writes = [r for r in requests if not _is_read(r, self.catalog)]
        if not requests or writes:
            raise UsageError("watch only re-polls reads (get, describe, modules); "
                             "use hold for motion")
        period = 1.0 / (hz or 2.0)
        tty = self.out.isatty()
        count = 0
        with Interrupt() as intr:
            due = self.clock()
            while not intr.hit:
                responses = self.ask_reader(text, separate=True)
                count += 1
                table = render_responses(responses, self.catalog, color=self.color)
                head = f"watch {text}  every {period:g} s  #{count}  (Ctrl-C stops)"
                self.out.write((_CLEAR if tty else "") + head + "\n" + table + "\n"
                               + ("" if tty else "\n"))
                self.out.flush()
                due += period
                now = self.clock()
                if due < now:  # fell behind: skip the missed polls, do not burst
                    due = now
                intr.wait(due - now)
        self.say()
        return EXIT_OK

    def cmd_hold(self, rest: str) -> int:
        """Send a motion request, feed the watchdog until Ctrl-C or SECONDS, then stop."""
        text, seconds = split_trailing_number(rest, "SECONDS", 0.0, MAX_HOLD_S)
        if not text:
            raise UsageError("usage: hold REQUEST [SECONDS]")
        requests = parse_requests(text)
        if not requests or all(_is_read(r, self.catalog) for r in requests):
            raise UsageError("hold keeps a motion request alive; this one does not move "
                             "anything (use watch for reads)")
        try:
            period = heartbeat_period(watchdog_timeout(self.ask_reader("robot:robot.get=()")))
        except ConnectionLost:
            period = heartbeat_period(None)
        tty = self.out.isatty()
        status = EXIT_OK
        tripped = False
        with Interrupt() as intr:
            responses, raw = self.ask_main(text)
            stop = stop_message(accepted_motion(requests, responses, self.catalog),
                                self.catalog.modules)
            try:
                if has_errors(responses):
                    self.show(responses, raw)
                    self.say("not holding: the robot refused the request")
                    return EXIT_ERROR
                start = self.clock()
                end = start + seconds if seconds else math.inf
                what = f"{seconds:g} s" if seconds else "Ctrl-C"
                self.say(f"holding {text} until {what}; Ctrl-C stops")
                next_beat = start + period
                while not intr.hit:
                    now = self.clock()
                    if now >= end:
                        break
                    intr.wait(min(next_beat, end) - now)
                    if intr.hit or self.clock() >= end:
                        break
                    beat, beat_raw = self.ask_main("")
                    if beat:
                        self.show(beat, beat_raw)
                    if self.watchdog_state() == "tripped":
                        tripped = True  # the robot stopped the motion: holding is over
                        break
                    next_beat = max(next_beat + period, self.clock())
                    if tty:
                        self.out.write(f"\rheld {self.clock() - start:5.1f} s")
                        self.out.flush()
                if tty:
                    self.out.write("\r\x1b[K")
                tripped = tripped or self.watchdog_state() == "tripped"
            finally:
                if stop:
                    status = self._send_stop(stop)
        if tripped:
            self.say("the watchdog tripped during the hold: the robot stopped the motion early "
                     "(robot:robot.get=() shows watchdog.state; the supervisor's log says why)")
            return EXIT_ERROR
        return status

    def watchdog_state(self) -> str | None:
        """`idle`, `armed` or `tripped`, read on the read-only connection (which never feeds
        the watchdog); None when the robot cannot say."""
        try:
            rows = self.ask_reader("robot:robot.get=()", separate=True)
        except ConnectionLost:
            return None
        for r in rows:
            if (r.module, r.device, r.prop) == ("robot", "watchdog", "state") and r.values:
                return str(r.values[0])
        return None

    def _send_stop(self, stop: str) -> int:
        try:
            responses, raw = self.ask_main(stop)
        except ConnectionLost as exc:
            self.say(f"cannot send {stop}: {exc}; the supervisor's watchdog stops the motion "
                     "when its feeder is gone")
            raise
        if responses:
            self.show(responses, raw)
        self.say(f"stopped: {stop}")
        return EXIT_ERROR if has_errors(responses) else EXIT_OK

    # -- prompt helpers -----------------------------------------------------------------------
    def toolbar(self, before: str) -> str:
        hint = param_hint(before, self.catalog)
        if hint is not None:
            return hint.text()
        if self.main is None:
            return f"disconnected from {self.address}: press Enter to reconnect"
        return f"{self.address}  Tab completes  help lists  Ctrl-D leaves"


# --------------------------------------------------------------------------- line sources


def open_history(path: Path) -> History:
    """History kept in `path` (directories made); in memory only if that cannot be written."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("a"):
            pass
    except OSError as exc:
        print(f"ramp-shell: history not saved ({path}: {exc.strerror or exc})",
              file=sys.stderr)
        return InMemoryHistory()
    return FileHistory(str(path))


def _prompt_lines(shell: Shell, history_file: Path) -> Iterator[str]:
    """Lines from a prompt_toolkit prompt with completion, toolbar and history."""
    from prompt_toolkit import PromptSession
    from prompt_toolkit.application import get_app
    from prompt_toolkit.completion import CompleteEvent, Completer, Completion
    from prompt_toolkit.document import Document
    from prompt_toolkit.output import ColorDepth

    class McpCompleter(Completer):
        def get_completions(self, document: Document,
                            complete_event: CompleteEvent) -> Iterator[Completion]:
            for c in complete(document.text_before_cursor, shell.catalog):
                yield Completion(c.text, start_position=c.start, display=c.display,
                                 display_meta=c.meta)

    history = open_history(history_file)

    def toolbar() -> str:
        return shell.toolbar(get_app().current_buffer.document.text_before_cursor)

    session: PromptSession[str] = PromptSession(
        history=history, completer=McpCompleter(), complete_while_typing=False,
        bottom_toolbar=toolbar,
        color_depth=None if shell.color else ColorDepth.MONOCHROME)
    while True:
        prompt = "ramp> " if shell.main is not None else "ramp (disconnected)> "
        try:
            yield session.prompt(prompt)
        except KeyboardInterrupt:
            continue
        except EOFError:
            return


def _plain_lines(stream: TextIO) -> Iterator[str]:
    """Lines from a pipe or file (`ramp-shell < script`), without a prompt."""
    for line in stream:
        yield line.rstrip("\r\n")


def interactive(shell: Shell, lines: Iterable[str]) -> int:
    """The read-run loop: errors are shown and the loop goes on; connection loss is offered
    a reconnect on the next line."""
    shell.interactive = True
    for line in lines:
        try:
            # Ctrl-C waits for the answer rather than tear a request from its response.
            with Interrupt():
                if shell.main is None:
                    if line.strip() in ("quit", "exit"):
                        return EXIT_OK
                    try:
                        shell.connect(monitor=True)
                    except ConnectionLost as exc:
                        shell.say(f"{exc}; press Enter to try again, or type quit")
                        continue
                    shell.say(f"reconnected to {shell.address}")
                    if not line.strip():
                        continue
                shell.run_line(line)
        except Quit:
            return EXIT_OK
        except ConnectionLost as exc:
            shell.close()
            shell.say(f"connection to {shell.address} lost: {exc}. Motion this shell started "
                      "stops on its own (watchdog). Press Enter to reconnect, or type quit.")
    return EXIT_OK


# --------------------------------------------------------------------------- main


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ramp-shell",
        description="Interactive MCP client: tab completion from describe, tables for gets, "
                    "watch and hold.")
    parser.add_argument("address", nargs="?", default=None,
                        help=f"HOST:PORT of the supervisor (default 127.0.0.1:{DEFAULT_PORT}); "
                             "mcps://HOST:PORT for mutual TLS with --cert/--key/--ca or "
                             "--identity")
    parser.add_argument("-c", dest="command", metavar="REQUEST",
                        help="send one line (an MCP message or a shell command such as "
                             "'hold ...'), print the answer and exit: 0 ok, 1 error "
                             "response, 2 no connection")
    parser.add_argument("--raw", action="store_true",
                        help="with -c: print the response line exactly as received")
    parser.add_argument("--no-color", action="store_true", help="never use colours")
    parser.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT,
                        help=f"seconds to wait for an answer (default {DEFAULT_TIMEOUT:g})")
    add_tls_arguments(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        tls, address = split_scheme(args.address or "")
        host, port = parse_address(address or None)
        ssl_context = context_for(tls, args)
    except ValueError as exc:
        parser.error(str(exc))
    if not (math.isfinite(args.timeout) and 0 < args.timeout <= MAX_TIMEOUT_S):
        parser.error(f"--timeout must be a positive number of seconds up to {MAX_TIMEOUT_S:g}, "
                     f"got {args.timeout:g}")
    color = (sys.stdout.isatty() and not args.no_color
             and not os.environ.get("NO_COLOR") and os.environ.get("TERM") != "dumb")
    shell = Shell(host, port, sys.stdout, color=color, timeout=args.timeout, raw=args.raw,
                  ssl_context=ssl_context)
    if args.command is not None:
        return one_shot(shell, args.command)
    try:
        shell.connect(monitor=True)
    except ConnectionLost as exc:
        print(f"ramp-shell: {exc}", file=sys.stderr)
        return EXIT_CONNECTION
    if sys.stdin.isatty() and sys.stdout.isatty():
        shell.say(f"connected to {shell.address}: modules "
                  f"{', '.join(shell.attached or []) or 'none'}. Type help, Tab completes.")
        lines: Iterable[str] = _prompt_lines(shell, history_path())
    else:
        lines = _plain_lines(sys.stdin)
    try:
        return interactive(shell, lines)
    except KeyboardInterrupt:  # Ctrl-C while reading a pipe; the prompt handles its own
        return 130
    finally:
        shell.close()


def one_shot(shell: Shell, command: str) -> int:
    """`-c`: every line of COMMAND runs in turn; the worst status wins."""
    status = EXIT_OK
    try:
        with Interrupt():
            shell.connect(describe=not shell.raw)
        for line in command.split("\n"):
            with Interrupt():
                status = max(status, shell.run_line(line))
        return status
    except Quit:
        return status
    except ConnectionLost as exc:
        print(f"ramp-shell: {exc}", file=sys.stderr)
        return EXIT_CONNECTION
    finally:
        shell.close()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
