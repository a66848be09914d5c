"""The README and the documentation pages as the docs tests read them: their fenced blocks,
their links and their headings.

A shell block (`sh`, `bash`, `shell`, `console`) that runs one of our commands is either run
by `tests/hil_sim/test_docs_commands.py` or marked illustrative by the line just before its
fence, with a reason for whoever edits the page:

    <!-- illustrative: needs a Sabertooth on a serial port -->

A `text` block marked `<!-- output -->` just before its fence is what the run block before it
prints, and the test compares the two.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"

SHELL_LANGS = frozenset({"sh", "bash", "shell", "console"})
ILLUSTRATIVE = re.compile(r"<!-- illustrative: (\S.*?) -->")
OUTPUT = "<!-- output -->"

#: A line that runs one of our commands: ramp, ramp-shell, ramp-teleop, ramp-autonomy, make,
#: python (-m) on our packages or the test suite, the scripts; with or without `.venv/bin/`,
#: `sudo` or environment assignments in front.
OURS = re.compile(
    r"^(?:sudo\s+)?(?:[A-Z_][A-Z0-9_]*=\S*\s+)*(?:\.venv/bin/)?"
    r"(?:(?:ramp|ramp-shell|ramp-teleop|ramp-autonomy|make)(?:\s|$)"
    r"|python3?\s+(?:-m\s+(?:ramp|bench|firmware_like|tests|pytest)\b|(?:tests|bench)/)"
    r"|scripts/)")


#: Commands that serve until stopped or run for minutes: a block with one must be marked
#: illustrative, never run by a test.
NEVER_ENDING = re.compile(r"(^|\s|/)(make (run|teleop|mission|test|bench|fuzz|campaign)\b"
                          r"|ramp run\b|ramp-teleop\b|ramp-autonomy --|--realtime)")


def runnable(block: Block) -> str | None:
    """Why a block that is not marked illustrative cannot be run by a test, or None."""
    for command in block.commands():
        if not OURS.match(command):
            return f"`{command}` is not a command of ours"
        if NEVER_ENDING.search(command):
            return f"`{command}` does not end by itself"
    return None


def pages() -> list[Path]:
    """The README and every Markdown page of the site (the build hook's folder excluded)."""
    found = sorted(p for p in DOCS.rglob("*.md") if "_hooks" not in p.parts)
    return [REPO / "README.md", *found]


def name(path: Path) -> str:
    return path.relative_to(REPO).as_posix()


@dataclass(frozen=True)
class Block:
    """One fenced block: where it opens, its language, its lines (indent removed), and the
    line just before its fence."""

    path: Path
    line: int           # 1-based line of the opening fence
    lang: str
    lines: tuple[str, ...]
    before: str

    @property
    def where(self) -> str:
        return f"{name(self.path)}:{self.line}"

    @property
    def illustrative(self) -> bool:
        return ILLUSTRATIVE.fullmatch(self.before.strip()) is not None

    def commands(self) -> list[str]:
        """The lines a shell would run (a console block's `$ ` lines), comments dropped."""
        if self.lang not in SHELL_LANGS:
            return []
        out = []
        for raw in self.lines:
            text = raw.strip()
            if self.lang == "console":
                if not text.startswith("$ "):
                    continue
                text = text[2:]
            if text and not text.startswith("#"):
                out.append(text)
        return out

    def ours(self) -> bool:
        return any(OURS.match(c) for c in self.commands())


_FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})(.*)$")


def blocks(path: Path) -> list[Block]:
    """Every fenced block of a page, nested fences inside a longer one left as its text."""
    lines = path.read_text(encoding="utf-8").split("\n")
    found: list[Block] = []
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        indent, fence, info = m.group(1), m.group(2), m.group(3).strip()
        body: list[str] = []
        j = i + 1
        while j < len(lines):
            close = lines[j].strip()
            if close.startswith(fence[0] * len(fence)) and set(close) == {fence[0]}:
                break
            body.append(lines[j][len(indent):] if lines[j].startswith(indent) else lines[j])
            j += 1
        before = lines[i - 1] if i > 0 else ""
        found.append(Block(path, i + 1, info.split()[0] if info else "", tuple(body), before))
        i = j + 1
    return found


def prose(path: Path) -> str:
    """The page without its fenced blocks and inline code: where links can be."""
    return re.sub(r"`[^`\n]*`", "", "\n".join(prose_lines(path)))


_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def links(path: Path) -> list[str]:
    """Every link and picture target in a page's prose."""
    return _LINK.findall(prose(path))


def slug(heading: str) -> str:
    """A heading's anchor as the site makes it (Python-Markdown's toc slugify)."""
    text = re.sub(r"`|\*\*?", "", heading)
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(path: Path) -> set[str]:
    """The anchors of a page's headings (outside fenced blocks)."""
    out: set[str] = set()
    for line in prose_lines(path):
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            out.add(slug(m.group(1)))
    return out


def prose_lines(path: Path) -> list[str]:
    """The page's lines outside its fenced blocks."""
    lines = path.read_text(encoding="utf-8").split("\n")
    spans = [(b.line - 1, b.line + len(b.lines)) for b in blocks(path)]
    return [line for n, line in enumerate(lines) if not any(a <= n <= b for a, b in spans)]
