"""YAML that remembers line numbers, so config errors can say `file:line: key.path: ...`.

A tiny generic helper with no knowledge of any config file: `load_marked(text)` parses with
PyYAML's SafeLoader and returns `MarkedMap`s (plain dicts with the line of the mapping and of
each key, and the keys given twice). Any loader (the autonomy's `autonomy.yaml`, world files,
later the backend's `ramp.yaml`) can walk the tree and point at the offending line.
"""

from __future__ import annotations

from typing import Any

import yaml


class MarkedMap(dict[Any, Any]):
    """A YAML mapping that remembers the line of itself and of each key (1-based)."""

    line: int = 0

    def __init__(self) -> None:
        super().__init__()
        self.lines: dict[Any, int] = {}
        self.duplicates: list[tuple[Any, int]] = []

    def line_of(self, key: Any) -> int:
        """The line of `key`, or of this mapping when the key is absent."""
        return self.lines.get(key, self.line)


class MarkedLoader(yaml.SafeLoader):
    """SafeLoader whose mappings are `MarkedMap`s."""


def _construct_mapping(loader: MarkedLoader, node: yaml.MappingNode) -> MarkedMap:
    loader.flatten_mapping(node)
    out = MarkedMap()
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


MarkedLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


class YamlSyntaxError(ValueError):
    """Text that is not YAML; `line` is 1-based (0 when unknown)."""

    def __init__(self, line: int, problem: str) -> None:
        self.line = line
        self.problem = problem
        super().__init__(f"line {line}: {problem}" if line else problem)


def load_marked(text: str) -> Any:
    """Parse one YAML document; mappings come back as `MarkedMap`. Raises YamlSyntaxError."""
    try:
        return yaml.load(text, Loader=MarkedLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else 0
        problem = getattr(exc, "problem", None) or str(exc)
        raise YamlSyntaxError(line, f"not valid YAML: {problem}") from None


def kind_of(value: Any) -> str:
    """Human words for a YAML value's type, for 'expected X, got Y' messages."""
    if value is None:
        return "nothing"
    return {dict: "a mapping", MarkedMap: "a mapping", list: "a list", str: "a string",
            int: "an integer", float: "a number", bool: "true/false"}.get(
        type(value), type(value).__name__)
