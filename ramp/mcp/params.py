"""Typed MCP parameters: each converts one raw token or says what it expected.

The parser keeps parameters as text; the module tables say what each function takes, and
these classes turn text into values. A wrong type, count or range is `bad_params`.
"""

from __future__ import annotations

import math
import re
from abc import ABC, abstractmethod
from typing import Any

# ASCII digits only ([0-9], not \d), and forms that cannot backtrack on long digit runs.
_INT = re.compile(r"[+-]?[0-9]+\Z")
_FLOAT = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
_NAME = re.compile(r"[A-Za-z0-9_-]{1,32}\Z")


class BadParam(ValueError):
    """A parameter token that does not fit its declared type or range."""


class Param(ABC):
    """One parameter of an MCP function."""

    @abstractmethod
    def convert(self, token: str) -> Any:
        """The value of `token`, or BadParam."""

    @abstractmethod
    def describe(self) -> str:
        """Type and range as `describe` shows it: `int -100..100`."""


class IntParam(Param):
    def __init__(self, lo: int, hi: int) -> None:
        self.lo, self.hi = lo, hi

    def convert(self, token: str) -> int:
        # Any decimal int, leading zeros too; the length bound only keeps int() cheap.
        if len(token) > 64 or not _INT.match(token):
            raise BadParam(token)
        v = int(token)
        if not self.lo <= v <= self.hi:
            raise BadParam(token)
        return v

    def describe(self) -> str:
        return f"int {self.lo}..{self.hi}"


class FloatParam(Param):
    """A finite float; an int literal is accepted. Bounds are inclusive, or open (`lo_open`)."""

    def __init__(self, lo: float | None = None, hi: float | None = None,
                 lo_open: bool = False) -> None:
        self.lo, self.hi, self.lo_open = lo, hi, lo_open

    def convert(self, token: str) -> float:
        if len(token) > 64 or not _FLOAT.match(token):
            raise BadParam(token)
        v = float(token)
        if not math.isfinite(v):
            raise BadParam(token)
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            raise BadParam(token)
        if self.hi is not None and v > self.hi:
            raise BadParam(token)
        return v

    def describe(self) -> str:
        if self.lo is None and self.hi is None:
            return "float"
        lo = "" if self.lo is None else _fmt(self.lo)
        hi = "" if self.hi is None else _fmt(self.hi)
        return f"float {'>' if self.lo_open else ''}{lo}..{hi}"


class FlagParam(Param):
    """0 or 1."""

    def convert(self, token: str) -> int:
        if token not in ("0", "1"):
            raise BadParam(token)
        return int(token)

    def describe(self) -> str:
        return "int 0..1"


class NameParam(Param):
    """1-32 letters, digits, `_` or `-`; some names may be reserved."""

    def __init__(self, reserved: tuple[str, ...] = ()) -> None:
        self.reserved = reserved

    def convert(self, token: str) -> str:
        if not _NAME.match(token) or token.lower() in self.reserved:
            raise BadParam(token)
        return token

    def describe(self) -> str:
        return "name"


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else str(x)


def convert_all(params: tuple[Param, ...], tokens: tuple[str, ...]) -> list[Any]:
    """Convert every token; BadParam on a wrong count or any bad token."""
    if len(tokens) != len(params):
        raise BadParam("count")
    return [p.convert(t) for p, t in zip(params, tokens, strict=True)]


def signature(function: str, params: tuple[Param, ...]) -> str:
    """`vel takes one int in -100..100` style text for bad_params details."""
    if not params:
        return f"{function} takes no parameters"
    if len(params) == 1:
        return f"{function} takes one {_phrase(params[0])}"
    words = ["one", "two", "three", "four"]
    n = words[len(params) - 1] if len(params) <= 4 else str(len(params))
    kinds = " and ".join(_phrase(p) for p in params)
    return f"{function} takes {n} parameter{'s' if len(params) > 1 else ''}: {kinds}"


def _phrase(p: Param) -> str:
    d = p.describe()
    if " " in d:
        t, rng = d.split(" ", 1)
        return f"{t} in {rng}"
    return d
