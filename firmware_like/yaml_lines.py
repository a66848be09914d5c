"""YAML that remembers where everything came from, for errors a person can act on.

`load(text)` parses with PyYAML's safe loader, but every mapping comes back as a `LinedMap`
(the line of the mapping and of each of its keys, plus keys given twice) and every sequence
as a `LinedList` (the line of each item), so a checker can say `world.yaml:4: rocks[1].d:
...`. The same idea as `ramp.config`'s loader, kept here so the emulators never import the
backend.
"""

from __future__ import annotations

from typing import Any

import yaml


class LinedMap(dict[Any, Any]):
    """A mapping with the 1-based line of itself (`line`) and of each key (`lines`)."""

    def __init__(self) -> None:
        super().__init__()
        self.line = 0
        self.lines: dict[Any, int] = {}
        self.duplicates: list[tuple[Any, int]] = []


class LinedList(list[Any]):
    """A sequence with the 1-based line of itself (`line`) and of each item (`lines`)."""

    def __init__(self) -> None:
        super().__init__()
        self.line = 0
        self.lines: list[int] = []


class _Loader(yaml.SafeLoader):
    pass


def _mapping(loader: _Loader, node: yaml.MappingNode) -> LinedMap:
    loader.flatten_mapping(node)
    out = LinedMap()
    out.line = node.start_mark.line + 1
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        value = loader.construct_object(value_node, deep=True)
        line = key_node.start_mark.line + 1
        if key in out:
            out.duplicates.append((key, line))
        out[key] = value
        out.lines[key] = line
    return out


def _sequence(loader: _Loader, node: yaml.SequenceNode) -> LinedList:
    out = LinedList()
    out.line = node.start_mark.line + 1
    for item in node.value:
        out.append(loader.construct_object(item, deep=True))
        out.lines.append(item.start_mark.line + 1)
    return out


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _sequence)


class YamlSyntaxError(ValueError):
    """Text that is not YAML; `line` is 1-based (0 when PyYAML could not tell)."""

    def __init__(self, problem: str, line: int) -> None:
        self.problem = problem
        self.line = line
        super().__init__(problem)


def load(text: str) -> Any:
    """Parse YAML text into LinedMap / LinedList / scalars; raises YamlSyntaxError."""
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else 0
        problem = getattr(exc, "problem", None) or str(exc)
        raise YamlSyntaxError(f"not valid YAML: {problem}", line) from exc


def kind(value: Any) -> str:
    """A value's YAML kind in words, for "expected X, got Y" messages."""
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return "true/false"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, str):
        return f"the text {value!r}"
    if isinstance(value, int | float):
        return repr(value)
    return type(value).__name__
