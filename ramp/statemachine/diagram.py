"""Draw the mission from the machine itself: a mermaid `stateDiagram-v2`, and the table of
states on the docs page `docs/autonomy/state-machine.md`.

Walks `machine.states` and `machine.events` (not `transitions`' graphviz extension, which
needs graphviz), so the picture is the machine: docs/autonomy/state-machine.md holds the output of
`python -m ramp.statemachine --mermaid`, and a test checks that it still is.

Drawing rules, for readability only (every edge is still there):
- one arrow per source, destination and condition; triggers that share all three are joined
  with ` / `; a condition reads `[name]`, or `[not name]` for an `unless`;
- the states of a group in `table.GROUPS` are drawn in one box, and an arrow that leaves
  every state of the box for the same place with the same label is drawn once, from the box;
- choice states (`StateSpec.choice`) are drawn as mermaid choices.
"""

from __future__ import annotations

from dataclasses import dataclass

from transitions import Machine
from transitions.core import Condition

from ramp.statemachine.table import FINAL, GROUPS, INITIAL, STATE, STATES

INDENT = "    "


@dataclass(frozen=True)
class Edge:
    source: str
    dest: str
    triggers: tuple[str, ...]
    guard: str  # "" when unconditional

    @property
    def label(self) -> str:
        text = " / ".join(self.triggers)
        return f"{text} [{self.guard}]" if self.guard else text


def condition_label(cond: Condition) -> str:
    name = cond.func if isinstance(cond.func, str) else getattr(cond.func, "__name__",
                                                                repr(cond.func))
    return name if cond.target else f"not {name}"


def edges(machine: Machine) -> list[Edge]:
    """Every transition of the machine, one edge per trigger, in state order."""
    order = {name: i for i, name in enumerate(machine.states)}
    found: list[tuple[int, int, Edge]] = []
    for trigger, event in machine.events.items():
        for source, transitions in event.transitions.items():
            for t in transitions:
                if t.dest is None:
                    continue
                guard = ", ".join(condition_label(c) for c in t.conditions)
                found.append((order[source], len(found), Edge(source, t.dest, (trigger,), guard)))
    return [e for _, _, e in sorted(found, key=lambda f: f[:2])]


def _collapse(all_edges: list[Edge]) -> list[Edge]:
    """Draw an edge that leaves every member of a group for one place once, from the group."""
    out = list(all_edges)
    for group in GROUPS:
        members = {s.name for s in STATES if s.group == group}
        by_target: dict[tuple[str, tuple[str, ...], str], set[str]] = {}
        for e in out:
            if e.source in members and e.dest not in members:
                by_target.setdefault((e.dest, e.triggers, e.guard), set()).add(e.source)
        for (dest, triggers, guard), sources in by_target.items():
            if sources == members:
                out = [e for e in out if not (e.source in members and e.dest == dest
                                              and e.triggers == triggers and e.guard == guard)]
                out.append(Edge(group, dest, triggers, guard))
    return out


def _merge(all_edges: list[Edge]) -> list[Edge]:
    """One arrow per source, destination and guard, its triggers joined, first one's place."""
    merged: dict[tuple[str, str, str], list[str]] = {}
    for e in all_edges:
        triggers = merged.setdefault((e.source, e.dest, e.guard), [])
        triggers += [t for t in e.triggers if t not in triggers]
    return [Edge(s, d, tuple(ts), g) for (s, d, g), ts in merged.items()]


def mermaid(machine: Machine) -> str:
    """The machine as a mermaid `stateDiagram-v2`, ending with a newline."""
    drawn = _merge(_collapse(edges(machine)))
    lines = ["stateDiagram-v2", f"{INDENT}[*] --> {INITIAL}"]
    for name in machine.states:
        if STATE[name].choice:
            lines.append(f"{INDENT}state {name} <<choice>>")
    inside: set[Edge] = set()
    for group, title in GROUPS.items():
        members = [s.name for s in STATES if s.group == group]
        lines.append(f'{INDENT}state "{title}" as {group} {{')
        for e in drawn:
            if e.source in members and e.dest in members:
                lines.append(f"{INDENT * 2}{e.source} --> {e.dest} : {e.label}")
                inside.add(e)
        lines.append(f"{INDENT}}}")
    for e in drawn:
        if e not in inside:
            lines.append(f"{INDENT}{e.source} --> {e.dest} : {e.label}")
    lines.append(f"{INDENT}{FINAL} --> [*]")
    return "\n".join(lines) + "\n"


def states_table() -> str:
    """The table of states (docs/autonomy/state-machine.md), from `table.STATES`, ending
    with a newline."""
    rows = ["| state | part | what it does | drives | stops the robot | timeout |",
            "|---|---|---|---|---|---|"]
    for s in STATES:
        timeout = f"{s.timeout_s:g} s" if s.timeout_s is not None else ""
        part = s.group or ("choice" if s.choice else "")
        rows.append(f"| `{s.name}` | {part} | {s.does} | {'yes' if s.drives else ''} "
                    f"| {'on entry' if s.halts else ''} | {timeout} |")
    return "\n".join(rows) + "\n"
