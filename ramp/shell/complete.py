"""Tab completion and parameter hints for `ramp-shell`: pure functions over a Catalog.

Completion looks only at the text before the cursor and at what the robot described, so it
is tested with strings; the prompt_toolkit adapter in `ramp.shell.cli` only converts the result.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ramp.shell.render import Catalog, FunctionInfo

#: Shell commands and what the completion menu says about them.
SHELL_COMMANDS: dict[str, str] = {
    "help": "list what the robot offers",
    "watch": "watch REQUEST [HZ]: re-poll a get",
    "hold": "hold REQUEST [SECONDS]: keep a motion alive",
    "reload": "describe the robot again",
    "quit": "leave the shell",
    "exit": "leave the shell",
}
#: Commands followed by a request, whose request part completes like a plain line.
REQUEST_COMMANDS = ("watch", "hold")

_COMMAND = re.compile(r"[ \t]*(watch|hold)[ \t]+")
_WORD = re.compile(r"[ \t]*([A-Za-z0-9_]*)")
_MODULE = re.compile(r"([A-Za-z0-9_]+):([A-Za-z0-9_]*)")
_DEVICE = re.compile(r"([A-Za-z0-9_]+):([A-Za-z0-9_]+)\.([A-Za-z0-9_]*)")
_PARAMS = re.compile(r"([A-Za-z0-9_]+):([A-Za-z0-9_]+)\.([A-Za-z0-9_]+)=\(([^)]*)")


@dataclass(frozen=True)
class Candidate:
    """One completion: `text` replaces the `-start` characters before the cursor."""

    text: str
    start: int
    display: str
    meta: str = ""


def split_command(line: str) -> tuple[str | None, str]:
    """(`watch` | `hold` | None, the request text after it)."""
    m = _COMMAND.match(line)
    if m:
        return m.group(1), line[m.end():]
    return None, line


def current_fragment(text: str) -> str:
    """The request being typed: whatever follows the last `)`, leading blanks dropped.

    Requests in one message are simply concatenated, so completion must restart after each.
    """
    return text[text.rfind(")") + 1:].lstrip(" \t")


def complete(before: str, catalog: Catalog) -> list[Candidate]:
    """Completions for the text before the cursor.

    Modules (and shell commands at the start of a line) after nothing, devices after
    `module:`, functions after `module:device.`; nothing inside the parentheses (see
    `param_hint`). After `watch` only functions that read are offered.
    """
    command, request = split_command(before)
    frag = current_fragment(request)
    reads_only = command == "watch"
    first = command is None and ")" not in request
    if (m := _WORD.fullmatch(frag)) is not None:
        word = m.group(1)
        out = [Candidate(f"{mod}:", -len(word), mod, "module")
               for mod in catalog.modules
               if mod.startswith(word) and _offers(catalog, mod, None, reads_only)]
        if first:
            for cmd, what in SHELL_COMMANDS.items():
                if cmd.startswith(word):
                    tail = " " if cmd in REQUEST_COMMANDS else ""
                    out.append(Candidate(cmd + tail, -len(word), cmd, what))
        return out
    if (m := _MODULE.fullmatch(frag)) is not None:
        module, word = m.groups()
        out = []
        for dev in catalog.devices(module):
            if dev.startswith(word) and _offers(catalog, module, dev, reads_only):
                names = ", ".join(fn.name for fn in catalog.functions_of(module, dev))
                out.append(Candidate(f"{dev}.", -len(word), dev, names))
        return out
    if (m := _DEVICE.fullmatch(frag)) is not None:
        module, dev, word = m.groups()
        return [Candidate(_insert(fn), -len(word), fn.name, fn.hint)
                for fn in catalog.functions_of(module, dev)
                if fn.name.startswith(word)
                and (not reads_only or catalog.is_read(module, dev, fn.name))]
    return []


def _insert(fn: FunctionInfo) -> str:
    """`vel=(` for a function with parameters, `get=()` for one without: ready to type on."""
    return f"{fn.name}=()" if not fn.params else f"{fn.name}=("


def _offers(catalog: Catalog, module: str, device: str | None, reads_only: bool) -> bool:
    if not reads_only:
        return True
    return any(catalog.is_read(module, fn.device, fn.name)
               and (device is None or fn.device == device)
               for fn in catalog.functions.get(module, ()))


@dataclass(frozen=True)
class Hint:
    """What the request being typed takes, and which parameter the cursor is on."""

    function: FunctionInfo
    index: int

    def text(self) -> str:
        """`base:lf_wheel.vel (int -100..100)`, the current parameter marked when several."""
        fn = self.function
        if not fn.params:
            return f"{fn.module}:{fn.device}.{fn.name} (no parameters)"
        if len(fn.params) == 1:
            return f"{fn.module}:{fn.device}.{fn.name} {fn.hint}"
        parts = [f"[{p}]" if i == self.index else p for i, p in enumerate(fn.params)]
        return f"{fn.module}:{fn.device}.{fn.name} ({', '.join(parts)})"


def param_hint(before: str, catalog: Catalog) -> Hint | None:
    """The parameter hint once `=(` is typed and until its `)`, or None."""
    _, request = split_command(before)
    frag = current_fragment(request)
    m = _PARAMS.fullmatch(frag)
    if m is None:
        return None
    module, device, name, typed = m.groups()
    fn = catalog.function(module, device, name)
    if fn is None:
        return None
    return Hint(fn, typed.count(","))
