"""The one YAML reader for every file RAMP reads: hardened, and with line marks.

Every YAML input (`ramp.yaml`, `autonomy.yaml`, world files, teleop profiles, anything new)
comes through here, so each gets the same limits and the same kind of error:

- `read_text(path)`: regular files only (a directory, a FIFO, `/dev/zero` or a terminal on
  `/dev/stdin` is refused before a byte is read, never waited on), at most `max_bytes`
  (checked on the open file's size first, and again while reading), UTF-8 (a bad byte is
  named with its line and column).
- Numbers as YAML 1.2 writes them: `5e-1` and `1.0e308` are floats, not the text PyYAML's
  YAML 1.1 rules make of them.
- `parse(text)` / `compose(text)`: PyYAML's safe loader with a nesting limit (`MAX_DEPTH`),
  an alias-expansion limit (`MAX_NODES`, counted at every use, so an alias bomb fails at
  once), NUL and other characters YAML forbids reported at their line, and a value Python
  cannot build (an integer of 100,000 digits) reported as a YAML error, not a ValueError.
- Mappings come back as `LinedMap` (the line of the mapping and of each key, keys given
  twice, merges as YAML says: an explicit key overrides a merged one), sequences as
  `LinedList` (the line of each item); a list or a mapping used as a key becomes a `BadKey`.

Errors are `YamlError(problem, line, file)`, whose text is `file:line: problem`; callers add
their key path and turn it into their own error type. Nothing here knows any file's schema.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from ramp.common.files import NotRegularFile, open_regular, why

#: A YAML input RAMP reads is a few kB; anything past this is refused before parsing.
MAX_FILE_BYTES = 1 << 20
#: Deepest nesting of mappings and lists (a real file needs 4 or 5).
MAX_DEPTH = 32
#: Most values a document may expand to once aliases are counted at every use.
MAX_NODES = 50_000

_MERGE_TAG = "tag:yaml.org,2002:merge"


class YamlError(ValueError):
    """A YAML input that cannot be used: `problem` at 1-based `line` (0: the whole file)."""

    def __init__(self, problem: str, line: int = 0, file: str = "") -> None:
        self.problem, self.line, self.file = problem, line, file
        where = f"{file}:{line}" if file and line else file or (f"line {line}" if line else "")
        super().__init__(f"{where}: {problem}" if where else problem)

    def in_file(self, file: str) -> YamlError:
        """The same error, naming `file`."""
        return YamlError(self.problem, self.line, file)


class LinedMap(dict[Any, Any]):
    """A YAML mapping with the 1-based line of itself (`line`) and of each key (`lines`)."""

    def __init__(self, line: int = 0) -> None:
        super().__init__()
        self.line = line
        self.lines: dict[Any, int] = {}
        self.duplicates: list[tuple[Any, int]] = []

    def line_of(self, key: Any) -> int:
        """The line of `key`, or of this mapping when the key is absent."""
        return self.lines.get(key, self.line)


class LinedList(list[Any]):
    """A YAML sequence with the 1-based line of itself (`line`) and of each item (`lines`)."""

    def __init__(self, line: int = 0) -> None:
        super().__init__()
        self.line = line
        self.lines: list[int] = []


class BadKey:
    """Stands in for a key YAML allows and no RAMP file can use (a list or a mapping)."""

    def __init__(self, kind: str, line: int) -> None:
        self.kind = kind
        self.line = line

    def __str__(self) -> str:
        return f"<{self.kind}>"


def kind_of(value: Any) -> str:
    """A value's type in words, for 'expected X, got Y' messages."""
    if value is None:
        return "nothing"
    for t, words in ((bool, "true/false"), (dict, "a mapping"), (list, "a list"),
                     (str, "a string"), (int, "an integer"), (float, "a number")):
        if isinstance(value, t):
            return words
    return type(value).__name__


def shown(value: Any) -> str:
    """A value as a person reads it in an error: `the text 'big'`, `-3`, `a mapping`."""
    if value is None or isinstance(value, bool | dict | list):
        return kind_of(value)
    if isinstance(value, str):
        return f"the text {value!r}"
    if isinstance(value, int | float):
        return repr(value)
    return type(value).__name__


# --------------------------------------------------------------------------- reading files


def read_text(path: str | Path, *, max_bytes: int = MAX_FILE_BYTES,
              what: str = "a YAML file") -> str:
    """The text of a regular file of at most `max_bytes`; YamlError naming the file otherwise.

    The file is opened by `ramp.common.files.open_regular` (never waits on a FIFO; checks
    the open descriptor), and its size is checked before a byte is read."""
    name = str(path)
    try:
        fd, size = open_regular(path)
    except NotRegularFile as exc:
        raise YamlError(exc.reason, file=name) from None
    try:
        if size > max_bytes:
            raise YamlError(f"larger than {max_bytes // 1024} KiB; {what} is a few kB",
                            file=name)
        chunks: list[bytes] = []
        got = 0
        while got <= max_bytes:
            try:
                chunk = os.read(fd, max_bytes + 1 - got)
            except OSError as exc:
                raise YamlError(f"cannot read: {why(exc)}", file=name) from None
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
        if got > max_bytes:
            raise YamlError(f"larger than {max_bytes // 1024} KiB (it grew while being read); "
                            f"{what} is a few kB", file=name)
    finally:
        os.close(fd)
    data = b"".join(chunks)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise YamlError(f"not UTF-8: byte 0x{data[exc.start]:02x} at column {column} (save "
                        "the file as UTF-8)", line, name) from None


def load_file(path: str | Path, *, max_bytes: int = MAX_FILE_BYTES,
              what: str = "a YAML file") -> Any:
    """`parse(read_text(path))`, errors naming the file."""
    text = read_text(path, max_bytes=max_bytes, what=what)
    try:
        return parse(text)
    except YamlError as exc:
        raise exc.in_file(str(path)) from None


# --------------------------------------------------------------------------- parsing


class _Loader(yaml.SafeLoader):
    """SafeLoader with limits on nesting and on alias expansion, and lined containers."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._sizes: dict[int, int] = {}  # id(node) -> values it expands to, aliases included
        self._aliased = False  # an alias was used: a size past the limit is an alias bomb

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            self._aliased = True
            return super().compose_node(parent, index)  # counted where it is used
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise yaml.composer.ComposerError(
                    None, None, f"nested deeper than {MAX_DEPTH} levels",
                    self.peek_event().start_mark)
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        if node is None:  # pragma: no cover - only at the end of a stream
            return node
        size = 1
        if isinstance(node, yaml.SequenceNode):
            size += sum(self._sizes.get(id(n), 1) for n in node.value)
        elif isinstance(node, yaml.MappingNode):
            size += sum(self._sizes.get(id(k), 1) + self._sizes.get(id(v), 1)
                        for k, v in node.value)
        if size > MAX_NODES:
            raise yaml.composer.ComposerError(
                None, None, f"expands to more than {MAX_NODES} values once its aliases are "
                "counted (an alias bomb?)" if self._aliased else _too_many(),
                node.start_mark)
        self._sizes[id(node)] = size
        return node

    def construct_object(self, node: Any, deep: bool = False) -> Any:
        """A scalar Python cannot build (an integer of 100,000 digits, the 13th month of a
        timestamp) is a YAML error at its line, not a ValueError from deep inside PyYAML."""
        try:
            return super().construct_object(node, deep)
        except (ValueError, OverflowError) as exc:
            raise yaml.constructor.ConstructorError(
                None, None, f"cannot read this value: {_shorten(str(exc), 120)}",
                node.start_mark) from None


def _mapping(loader: _Loader, node: yaml.MappingNode) -> LinedMap:
    explicit = sum(1 for k, _ in node.value if k.tag != _MERGE_TAG)
    loader.flatten_mapping(node)
    merged = len(node.value) - explicit  # flatten_mapping puts merged pairs first
    out = LinedMap(node.start_mark.line + 1)
    explicit_keys: set[Any] = set()
    for i, (key_node, value_node) in enumerate(node.value):
        key = loader.construct_object(key_node, deep=True)
        value = loader.construct_object(value_node, deep=True)
        line = key_node.start_mark.line + 1
        try:
            hash(key)
        except TypeError:
            key = BadKey(kind_of(key), line)
        if i >= merged:  # a merged key is overridden by an explicit one, as YAML says
            if key in explicit_keys:
                out.duplicates.append((key, line))
            explicit_keys.add(key)
        out[key] = value
        out.lines[key] = line
    return out


def _sequence(loader: _Loader, node: yaml.SequenceNode) -> LinedList:
    out = LinedList(node.start_mark.line + 1)
    for item in node.value:
        out.append(loader.construct_object(item, deep=True))
        out.lines.append(item.start_mark.line + 1)
    return out


# YAML 1.1 (PyYAML) reads `5e-1`, `6e2` and `1.0e308` as text: a float needs a dot and a
# signed exponent there. YAML 1.2, JSON and every person read them as numbers, and the error
# that followed (`'5e-1' is not a timeout in seconds (0.05-60)`) named a value in range.
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _sequence)


def parse(text: str) -> Any:
    """One YAML document -> LinedMap / LinedList / scalars (None when empty); YamlError."""
    return _run(text, lambda loader: loader.get_single_data())


def parse_mapping(text: str, what: str = "a mapping") -> LinedMap:
    """A document that must be a mapping (an empty one is an empty mapping at line 1);
    YamlError `expected {what} at the top, got ...` otherwise."""
    root = parse(text)
    if root is None:
        return LinedMap(1)
    if not isinstance(root, LinedMap):
        raise YamlError(f"expected {what} at the top, got {kind_of(root)}", 1)
    return root


def compose(text: str) -> yaml.Node | None:
    """One YAML document as PyYAML nodes (for readers that walk marks), with the same limits
    as `parse`; YamlError."""
    node: yaml.Node | None = _run(text, lambda loader: loader.get_single_node())
    return node


def construct(node: yaml.Node) -> Any:
    """The Python value of one node from `compose` (lined containers, the same limits)."""
    return _run("", lambda loader: loader.construct_document(node))


def _too_many() -> str:
    return (f"holds more than {MAX_NODES} values (the limit on any YAML file RAMP reads; "
            "a config or a world file holds a few hundred)")


def _count_values(text: str) -> None:
    """Refuse a document of more than `MAX_NODES` values before the (slow, pure-Python)
    composer builds it: libyaml's parser counts its events in a fraction of the time (a
    12,000-rock world file: 0.2 s to the limit instead of 5 s, then a wrong "alias bomb?").
    Aliases are left to the composer, which counts them at each use; anything libyaml
    cannot parse is left to it too, so its errors read as they always did."""
    parser = getattr(yaml, "CSafeLoader", None)
    if parser is None or len(text) < MAX_NODES:  # each value takes a byte at least
        return
    values = (yaml.ScalarEvent, yaml.SequenceStartEvent, yaml.MappingStartEvent)
    p = parser(text)
    try:
        n = 0
        while p.check_event():
            event = p.get_event()
            if isinstance(event, values):
                n += 1
                if n > MAX_NODES:
                    mark = event.start_mark
                    raise YamlError(_too_many(), mark.line + 1 if mark is not None else 0)
    except yaml.YAMLError:
        return
    finally:
        p.dispose()


def _run(text: str, step: Callable[[_Loader], Any]) -> Any:
    loader: _Loader | None = None
    if text:
        _count_values(text)
    try:
        loader = _Loader(text)  # the reader checks for NUL and other forbidden characters here
        return step(loader)
    except yaml.YAMLError as exc:
        raise _error(exc, text) from None
    except RecursionError:  # pragma: no cover - MAX_DEPTH keeps the composer far from it
        raise YamlError("not valid YAML: nested too deeply") from None
    finally:
        if loader is not None:
            loader.dispose()


def _error(exc: yaml.YAMLError, text: str) -> YamlError:
    """`line: not valid YAML: problem`, for the parser's errors and the reader's (a NUL byte
    or another character YAML refuses, which carry a position instead of a mark)."""
    mark = getattr(exc, "problem_mark", None)
    line = mark.line + 1 if mark is not None else 0
    problem = getattr(exc, "problem", None)
    position = getattr(exc, "position", None)
    if isinstance(exc, yaml.reader.ReaderError) and isinstance(position, int):
        line = text.count("\n", 0, position) + 1
        problem = f"character #x{exc.character:04x} is not allowed in YAML" \
            if isinstance(exc.character, int) else exc.reason
    return YamlError(f"not valid YAML: {_shorten(str(problem or exc), 200)}", line)


def _shorten(text: str, limit: int) -> str:
    """A value may be a megabyte long: cut, saying how long it was."""
    return text if len(text) <= limit else f"{text[:limit - 20]}... ({len(text)} characters)"
