"""Typed fields for configuration blocks.

Drivers and modules declare their YAML keys once as `Field`s; the config loader checks
values against them and words errors the same way everywhere
(`140 is not a Sabertooth address (128-135)`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

REQUIRED: Any = object()


@dataclass(frozen=True)
class Field:
    """One configuration key: its type, default, range and what it means."""

    kind: type  # int, float, str, bool, list or dict
    default: Any = REQUIRED
    lo: float | None = None
    hi: float | None = None
    choices: tuple[Any, ...] | None = None
    what: str = ""  # "a Sabertooth address": used in error messages

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def expected(self) -> str:
        """Human words for what this key takes."""
        if self.what:
            base = self.what
        else:
            base = {int: "an integer", float: "a number", str: "a string", bool: "true or false",
                    list: "a list", dict: "a mapping"}.get(self.kind, self.kind.__name__)
        if self.choices is not None:
            return f"{base} (one of {', '.join(str(c) for c in self.choices)})"
        if self.lo is not None and self.hi is not None:
            return f"{base} ({_num(self.lo)}-{_num(self.hi)})"
        if self.lo is not None:
            return f"{base} (>= {_num(self.lo)})"
        if self.hi is not None:
            return f"{base} (<= {_num(self.hi)})"
        return base

    def check(self, value: Any) -> Any:
        """Return the value converted to `kind`, or raise ValueError saying what was expected."""
        v = value
        if self.kind is float and isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        if self.kind is str and isinstance(v, int | float) and not isinstance(v, bool):
            v = str(v)
        if not isinstance(v, self.kind) or (self.kind is not bool and isinstance(v, bool)):
            raise ValueError(f"{shorten(repr(value))} is not {self.expected()}")
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{shorten(repr(value))} is not {self.expected()}")
        if self.choices is not None and v not in self.choices:
            raise ValueError(f"{shorten(repr(value))} is not {self.expected()}")
        if isinstance(v, int | float) and not isinstance(v, bool) and (
            (self.lo is not None and v < self.lo) or (self.hi is not None and v > self.hi)
        ):
            raise ValueError(f"{shorten(repr(value))} is not {self.expected()}")
        return v


def shorten(text: str, limit: int = 60) -> str:
    """`text` cut to `limit` characters, saying how long it was: error messages quote what
    was given, and a value may be a megabyte long."""
    if len(text) <= limit:
        return text
    return f"{text[:limit - 20]}... ({len(text)} characters)"


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else str(x)


def apply_fields(fields: dict[str, Field], values: dict[str, Any]) -> dict[str, Any]:
    """Check a block of values against its fields; unknown and missing keys are errors.

    Raises KeyError(key, message) style errors as `ValueError` carrying the key in
    `args[1]`, so the loader can point at the right line.
    """
    out: dict[str, Any] = {}
    for key in values:
        if key not in fields:
            known = ", ".join(sorted(fields)) or "none"
            raise FieldError(key, f"unknown key (expected one of: {known})")
    for key, f in fields.items():
        if key in values:
            try:
                out[key] = f.check(values[key])
            except ValueError as exc:
                raise FieldError(key, str(exc)) from None
        elif f.required:
            raise FieldError(key, f"missing; expected {f.expected()}")
        else:
            out[key] = f.default
    return out


class FieldError(ValueError):
    """A bad key inside a block: `key` is relative to that block."""

    def __init__(self, key: str, message: str) -> None:
        self.key = key
        self.message = message
        super().__init__(f"{key}: {message}")
