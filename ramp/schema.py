"""Typed fields for configuration blocks, and the one check every block goes through.

Drivers and modules declare their YAML keys once as `Field`s, and the checks that span
several keys of a block as `Rule`s beside them (a `Block` holds both). `validate` is the
only code that checks a block: the config loader runs it on every block of `ramp.yaml` (and
points at the line), and a driver or module built from values runs the same function
(`check_block`), so a mistake is worded the same everywhere
(`140 is not a Sabertooth address (128-135)`) and is always a `ConfigError`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from ramp.errors import ConfigError

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
            try:
                v = float(v)
            except OverflowError:  # an integer of hundreds of digits: no float holds it
                raise ValueError(f"{shorten(repr(value))} is not {self.expected()}") from None
        if self.kind is str and isinstance(v, int | float) and not isinstance(v, bool):
            v = str(v)
        if not isinstance(v, self.kind) or (self.kind is not bool and isinstance(v, bool)):
            raise ValueError(f"{shorten(repr(value))} is not {self.expected()}")
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{shorten(repr(value))} is not {self.expected()}")
        if isinstance(v, str) and self.required and not v.strip():
            # `port: ""` passed the check, then the bus retried "cannot open : ..." for ever
            raise ValueError(f"{shorten(repr(value))} is not {self.expected()}")
        if self.choices is not None and v not in self.choices:
            raise ValueError(f"{shorten(repr(value))} is not {self.expected()}")
        if isinstance(v, int | float) and not isinstance(v, bool) and (
            (self.lo is not None and v < self.lo) or (self.hi is not None and v > self.hi)
        ):
            raise ValueError(f"{shorten(repr(value))} is not {self.expected()}")
        return v


@dataclass(frozen=True)
class Rule:
    """A check spanning several keys of one block (thresholds in order, two calibration points
    apart), declared beside the block's fields. It sees the block's checked values."""

    holds: Callable[[Mapping[str, Any]], bool]
    message: str
    #: Where it is reported, relative to the block ("" is the block itself).
    key: str = ""


class Block(dict[str, Field]):
    """A config block's keys (name -> `Field`) and the `Rule`s that span them."""

    def __init__(self, fields: Mapping[str, Field] | None = None,
                 rules: Iterable[Rule] = ()) -> None:
        super().__init__(fields or {})
        self.rules: tuple[Rule, ...] = tuple(rules)


Problem = tuple[str, str]  # (key relative to the block, "" for the block itself; message)


def validate(block: Mapping[str, Field], values: Mapping[str, Any] | None,
             skip: Iterable[str] = ()) -> tuple[dict[str, Any], list[Problem]]:
    """The one check of a config block: unknown keys, then each field, then the block's
    rules (only once every field is good). Returns the values (converted, defaults filled
    in; a bad key gets its default) and every problem found, in that order. Keys in `skip`
    belong to someone else (a bus entry's `driver`)."""
    given = values or {}
    skipped = set(skip)
    problems: list[Problem] = []
    for key in given:
        if key not in block and key not in skipped:
            known = ", ".join(sorted([*block, *skipped])) or "none"
            problems.append((str(key), f"unknown key (expected one of: {known})"))
    out: dict[str, Any] = {}
    bad_field = False
    for key, f in block.items():
        if key in given:
            try:
                out[key] = f.check(given[key])
                continue
            except ValueError as exc:
                problems.append((key, str(exc)))
        elif f.required:
            problems.append((key, f"missing; expected {f.expected()}"))
        else:
            out[key] = f.default
            continue
        bad_field = True
        if not f.required:
            out[key] = f.default
    if not bad_field:
        problems += [(r.key, r.message) for r in getattr(block, "rules", ()) if not r.holds(out)]
    return out, problems


def check_block(block: Mapping[str, Field], values: Mapping[str, Any] | None, where: str,
                skip: Iterable[str] = ()) -> dict[str, Any]:
    """`validate`, raising the first problem as a `ConfigError` keyed `where.key`."""
    out, problems = validate(block, values, skip)
    if problems:
        key, message = problems[0]
        raise ConfigError(message, key=f"{where}.{key}" if key and where else key or where)
    return out


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
