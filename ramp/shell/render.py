"""What `ramp-shell` knows about a robot, and how it shows answers: pure functions only.

The catalog is built from `describe` answers (SPEC 2.2), never from tables written here, so a
new module or device shows up in the shell's help, completion and units without a change to
this file. Rendering turns response values into text and never touches a socket or a
terminal, which keeps every rule testable with plain values.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from ramp.mcp.describe import (
    READ_FUNCTIONS,
    Catalog,
    FunctionInfo,
    PropertyInfo,
    build_catalog,
    error_text,
)
from ramp.mcp.describe import value_text as _text
from ramp.mcp.messages import Response, Value
from ramp.mcp.protocol import format_value

__all__ = ["READ_FUNCTIONS", "Catalog", "FunctionInfo", "PropertyInfo", "build_catalog",
           "error_text", "has_errors", "modules_listed", "render_help", "render_responses",
           "render_table", "render_value", "wrap_items"]

_BOLD = "\x1b[1m"
_RED = "\x1b[31m"
_DIM = "\x1b[2m"
_RESET = "\x1b[0m"


# --------------------------------------------------------------------------- answers


def render_value(values: Sequence[Value], unit: str = "") -> str:
    """`20.956 V`, `140, 9258, 25326`, `base, ble`: values as MCP prints them, then the unit."""
    text = ", ".join(_text(v) for v in values)
    return f"{text} {unit}" if unit and text else text


def render_responses(responses: Sequence[Response], catalog: Catalog | None = None, *,
                     color: bool = False) -> str:
    """One response message as text: a table of rows, then one line per error.

    An empty message (every action accepted) reads `ok`. No trailing newline.
    """
    if not responses:
        return "ok"
    rows = [r for r in responses if r.prop != "error"]
    errors = [r for r in responses if r.prop == "error"]
    lines: list[str] = []
    if rows:
        table = [(r.module, r.device, r.prop,
                  render_value(r.values, catalog.unit(r.module, r.device, r.prop)
                               if catalog else ""))
                 for r in rows]
        lines.extend(render_table(("module", "device", "property", "value"), table,
                                  color=color))
    for r in errors:
        line = f"error  {r.module}:{r.device}  {error_text(r)}"
        lines.append(f"{_RED}{line}{_RESET}" if color else line)
    return "\n".join(lines)


def render_table(header: Sequence[str], rows: Sequence[Sequence[str]], *,
                 color: bool = False) -> list[str]:
    """Left-aligned columns two spaces apart; the last column is not padded."""
    widths = [len(h) for h in header]
    for row in rows:
        for i, cell in enumerate(row):
            widths[i] = max(widths[i], len(cell))

    def line(cells: Sequence[str]) -> str:
        padded = [c.ljust(w) for c, w in zip(cells[:-1], widths, strict=False)]
        return "  ".join([*padded, cells[-1]]).rstrip()

    head = line(header)
    out = [f"{_BOLD}{head}{_RESET}" if color else head]
    out.extend(line(row) for row in rows)
    return out


def has_errors(responses: Iterable[Response]) -> bool:
    return any(r.prop == "error" for r in responses)


def modules_listed(responses: Iterable[Response]) -> list[str] | None:
    """The module list if the answer contains `robot:robot.modules=(...)`, else None."""
    for r in responses:
        if r.module == "robot" and r.device == "robot" and r.prop == "modules":
            return [_text(v) for v in r.values]
    return None


# --------------------------------------------------------------------------- help

SAFETY = """\
Safety: this shell never keeps motors running by itself.
  A motion request typed at the prompt arms the supervisor's watchdog ({timeout}): unless you
  type another line within it (an empty line is a heartbeat), the robot stops.
  `hold REQUEST [SECONDS]` keeps a motion going: it sends heartbeats until Ctrl-C or SECONDS,
  then sends the module's stop. `watch` polls over a second connection, so it never feeds
  the watchdog. `robot:robot.stop=()` stops everything, from any client, always."""

HELP_WIDTH = 96

COMMANDS = (
    ("help", "this list"),
    ("watch REQUEST [HZ]", "re-poll a get (default 2 Hz) and redraw it until Ctrl-C"),
    ("hold REQUEST [SECONDS]", "send a motion, keep it alive until Ctrl-C or SECONDS, stop"),
    ("reload", "ask the robot to describe itself again"),
    ("quit, exit, Ctrl-D", "leave"),
)


def wrap_items(first: str, items: Sequence[str], indent: str, width: int) -> list[str]:
    """`items` joined by `, ` over lines of at most `width`, never splitting an item."""
    lines: list[str] = []
    line = first
    for i, item in enumerate(items):
        piece = item + ("," if i < len(items) - 1 else "")
        if line not in (first, indent) and len(line) + 1 + len(piece) > width:
            lines.append(line)
            line = indent
        line += piece if line in (first, indent) else " " + piece
    lines.append(line)
    return lines


def render_help(catalog: Catalog, *, watchdog_timeout: float | None = None,
                color: bool = False) -> str:
    """What the robot offers, grouped by module, then the shell's own commands and safety."""

    def head(text: str) -> str:
        return f"{_BOLD}{text}{_RESET}" if color else text

    lines: list[str] = []
    for module in catalog.modules:
        lines.append(head(module))
        if module in catalog.problems:
            lines.append(f"  (cannot describe: {catalog.problems[module]})")
        for fn in catalog.functions.get(module, ()):
            lines.append(f"  {fn.usage}")
        props = catalog.properties.get(module, ())
        if props:
            items = [f"{p.device}.{p.name}" + (f" [{p.unit}]" if p.unit else "")
                     for p in props]
            lines.extend(wrap_items("  get rows: ", items, "    ", HELP_WIDTH))
    lines.append(head("shell commands"))
    width = max(len(c) for c, _ in COMMANDS)
    for cmd, what in COMMANDS:
        lines.append(f"  {cmd.ljust(width)}  {what}")
    lines.append("  Several requests may share a line; each line is one MCP message.")
    timeout = (f"timeout {format_value(watchdog_timeout)} s" if watchdog_timeout is not None
               else "see robot:watchdog.timeout")
    lines.append(SAFETY.format(timeout=timeout))
    return "\n".join(lines)
