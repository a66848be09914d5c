"""The `when` grammar of an interlock rule (SPEC 11): our own, small, never `eval`.

    condition  = or ;
    or         = and, { "or", and } ;
    and        = not, { "and", not } ;
    not        = "not", not | atom ;
    atom       = "(", condition, ")" | comparison ;
    comparison = property, op, number | number, op, property ;
    op         = "<" | "<=" | ">" | ">=" | "==" | "!=" ;
    property   = MODULE, ":", DEVICE, ".", PROPERTY ;   (MCP names: letters, digits, _)

Precedence is `not` > `and` > `or`, as in most languages; parentheses group. A property
stands for the first value of its get row. `number op property` is read as the mirrored
`property op' number`, so every comparison in the tree has its property on the left.

The text is cut into tokens by one regular expression per token kind, then a recursive
descent builds a tree of frozen dataclasses (`Compare`, `Not`, `All`, `Any_`). Nothing here
knows a robot: `ramp.config.interlocks` checks the names against the module tables, and
`compile_condition` turns a tree into a predicate over the values of its properties. Any text
at all either parses or raises `ConditionError` with the column, nothing else: the parser is
bounded in length and in nesting, so a hostile file cannot exhaust the stack.

`str(tree)` prints the canonical text (single spaces, the fewest parentheses that keep the
tree's shape); parsing it gives the same tree back, which the property-based tests check.
"""

from __future__ import annotations

import math
import operator
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

#: The longest `when` text accepted (a real rule is a line or two).
MAX_TEXT = 2000
#: The deepest nesting of parentheses and `not`s accepted.
MAX_DEPTH = 32

OPS: dict[str, Callable[[float, float], bool]] = {
    "<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge,
    "==": operator.eq, "!=": operator.ne,
}
#: `a op b` is `b MIRROR[op] a`.
MIRROR = {"<": ">", "<=": ">=", ">": "<", ">=": "<=", "==": "==", "!=": "!="}
KEYWORDS = ("and", "or", "not")

_NAME = r"[A-Za-z0-9_]{1,32}"
_TOKENS = re.compile(
    rf"(?P<space>[ \t]+)"
    rf"|(?P<prop>{_NAME}:{_NAME}\.{_NAME})(?![A-Za-z0-9_.:])"
    r"|(?P<number>[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]{1,3})?)"
    r"(?![A-Za-z0-9_.:])"
    r"|(?P<word>[A-Za-z_][A-Za-z0-9_]*)(?![A-Za-z0-9_.:])"
    r"|(?P<op><=|>=|==|!=|<|>)"
    r"|(?P<paren>[()])")


class ConditionError(ValueError):
    """A `when` text that is not a condition; `column` is 1-based (0: the whole text)."""

    def __init__(self, message: str, column: int = 0) -> None:
        self.message = message
        self.column = column
        super().__init__(f"{message} at column {column}" if column else message)


# -- the tree -------------------------------------------------------------------------------

@dataclass(frozen=True)
class Compare:
    """`property op value`: true when the property's first value compares so."""

    prop: str
    op: str
    value: float

    def __str__(self) -> str:
        return f"{self.prop} {self.op} {_number(self.value)}"


@dataclass(frozen=True)
class Not:
    arg: Node

    def __str__(self) -> str:
        inner = str(self.arg)
        return f"not {inner}" if isinstance(self.arg, Compare | Not) else f"not ({inner})"


@dataclass(frozen=True)
class All:
    """`a and b and ...` (two or more)."""

    args: tuple[Node, ...]

    def __str__(self) -> str:
        return " and ".join(f"({a})" if isinstance(a, All | AnyOf) else str(a)
                            for a in self.args)


@dataclass(frozen=True)
class AnyOf:
    """`a or b or ...` (two or more)."""

    args: tuple[Node, ...]

    def __str__(self) -> str:
        return " or ".join(f"({a})" if isinstance(a, AnyOf) else str(a) for a in self.args)


Node = Compare | Not | All | AnyOf


def _number(x: float) -> str:
    """Shortest text that reads back as the same number (`0.2`, `30`, `1e-05`)."""
    x = float(x)
    if x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def properties(node: Node) -> list[str]:
    """The properties a condition reads, each once, in the order they first appear."""
    out: list[str] = []
    stack: list[Node] = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, Compare):
            if n.prop not in out:
                out.append(n.prop)
        elif isinstance(n, Not):
            stack.append(n.arg)
        else:
            stack.extend(reversed(n.args))
    return out


def comparisons(node: Node) -> list[Compare]:
    """Every comparison of a condition, in the order they appear: a condition's value can
    change only when one of these does (what lets the interlocks skip a rule)."""
    out: list[Compare] = []
    stack: list[Node] = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, Compare):
            out.append(n)
        elif isinstance(n, Not):
            stack.append(n.arg)
        else:
            stack.extend(reversed(n.args))
    return out


# -- parsing ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Token:
    kind: str  # prop, number, word, op, paren, end
    text: str
    column: int


def tokenize(text: str) -> list[_Token]:
    """The tokens of `text`, ending with an `end` token; ConditionError on anything else."""
    if not isinstance(text, str):
        raise ConditionError("expected the condition as text")
    if len(text) > MAX_TEXT:
        raise ConditionError(f"longer than {MAX_TEXT} characters")
    out: list[_Token] = []
    pos = 0
    while pos < len(text):
        m = _TOKENS.match(text, pos)
        if m is None:
            raise ConditionError(_unexpected(text, pos), pos + 1)
        kind = m.lastgroup or ""
        if kind != "space":
            out.append(_Token(kind, m.group(), pos + 1))
        pos = m.end()
    out.append(_Token("end", "", len(text) + 1))
    return out


def _unexpected(text: str, pos: int) -> str:
    ch = text[pos]
    if ch in ":." or re.match(r"[A-Za-z0-9_]+[:.]", text[pos:pos + 40]):
        return ("expected a property MODULE:DEVICE.PROPERTY (names of 1-32 letters, digits "
                "or _)")
    if ch == "=":
        return "unexpected '=' (compare with ==)"
    if ch in "&|!":
        return f"unexpected {ch!r} (use and, or, not)"
    shown = ch if 32 <= ord(ch) < 127 else f"\\x{ord(ch):02x}" if ord(ch) < 256 \
        else f"\\u{ord(ch):04x}"
    return f"unexpected character {shown!r}"


class _Parser:
    def __init__(self, text: str) -> None:
        self.tokens = tokenize(text)
        self.i = 0
        self.depth = 0

    @property
    def tok(self) -> _Token:
        return self.tokens[self.i]

    def take(self) -> _Token:
        t = self.tokens[self.i]
        self.i += 1
        return t

    def is_word(self, word: str) -> bool:
        return self.tok.kind == "word" and self.tok.text == word

    def parse(self) -> Node:
        if self.tok.kind == "end":
            raise ConditionError("empty condition; expected a comparison such as "
                                 "ble:lift.pos < 0.2")
        node = self.or_()
        if self.tok.kind != "end":
            raise ConditionError(f"unexpected {_shown(self.tok)} (expected and, or, or the "
                                 "end)", self.tok.column)
        return node

    def or_(self) -> Node:
        args = [self.and_()]
        while self.is_word("or"):
            self.take()
            args.append(self.and_())
        return args[0] if len(args) == 1 else AnyOf(tuple(args))

    def and_(self) -> Node:
        args = [self.not_()]
        while self.is_word("and"):
            self.take()
            args.append(self.not_())
        return args[0] if len(args) == 1 else All(tuple(args))

    def not_(self) -> Node:
        if self.is_word("not"):
            self.take()
            with _Deeper(self):
                return Not(self.not_())
        return self.atom()

    def atom(self) -> Node:
        t = self.tok
        if t.kind == "paren" and t.text == "(":
            self.take()
            with _Deeper(self):
                node = self.or_()
            if not (self.tok.kind == "paren" and self.tok.text == ")"):
                raise ConditionError(f"expected ')' to close the '(' at column {t.column}, "
                                     f"got {_shown(self.tok)}", self.tok.column)
            self.take()
            return node
        return self.comparison()

    def comparison(self) -> Compare:
        left = self.take()
        if left.kind not in ("prop", "number"):
            raise ConditionError(f"expected a comparison (MODULE:DEVICE.PROPERTY op NUMBER), "
                                 f"got {_shown(left)}", left.column)
        op = self.take()
        if op.kind != "op":
            raise ConditionError(f"expected one of < <= > >= == != after {left.text}, got "
                                 f"{_shown(op)}", op.column)
        right = self.take()
        want = "number" if left.kind == "prop" else "prop"
        if right.kind != want:
            what = "a number" if want == "number" else "a property MODULE:DEVICE.PROPERTY"
            raise ConditionError(f"expected {what} after {op.text}, got {_shown(right)} (a "
                                 "comparison is between a property and a number)", right.column)
        if left.kind == "prop":
            return Compare(left.text, op.text, _value(right))
        return Compare(right.text, MIRROR[op.text], _value(left))


class _Deeper:
    """Counts nesting; past MAX_DEPTH the text is refused (no deep recursion)."""

    def __init__(self, parser: _Parser) -> None:
        self.parser = parser

    def __enter__(self) -> None:
        self.parser.depth += 1
        if self.parser.depth > MAX_DEPTH:
            raise ConditionError(f"nested deeper than {MAX_DEPTH} levels", self.parser.tok.column)

    def __exit__(self, *exc: object) -> None:
        self.parser.depth -= 1


def _value(t: _Token) -> float:
    v = float(t.text)
    if not math.isfinite(v):
        raise ConditionError(f"{t.text} is not a finite number", t.column)
    return v


def _shown(t: _Token) -> str:
    if t.kind == "end":
        return "the end"
    return repr(t.text)


def parse_condition(text: str) -> Node:
    """The tree of a `when` text; ConditionError (with its column) if it is not one."""
    return _Parser(text).parse()


# -- evaluation ------------------------------------------------------------------------------

Predicate = Callable[[Sequence[float]], bool]


#: One closure per operator: a comparison in a tick is one index and one compare.
_COMPARE: dict[str, Callable[[int, float], Predicate]] = {
    "<": lambda i, k: lambda v: v[i] < k,
    "<=": lambda i, k: lambda v: v[i] <= k,
    ">": lambda i, k: lambda v: v[i] > k,
    ">=": lambda i, k: lambda v: v[i] >= k,
    "==": lambda i, k: lambda v: v[i] == k,
    "!=": lambda i, k: lambda v: v[i] != k,
}


def compile_condition(node: Node, index: dict[str, int]) -> Predicate:
    """A predicate over the values of the condition's properties (`index[prop]` is where
    each sits): closures, so a tick's evaluation does no tree walking or dispatch."""
    if isinstance(node, Compare):
        return _COMPARE[node.op](index[node.prop], node.value)
    if isinstance(node, Not):
        inner = compile_condition(node.arg, index)
        return lambda v: not inner(v)
    parts = tuple(compile_condition(a, index) for a in node.args)
    if len(parts) == 2:  # the common case, without a generator
        a, b = parts
        if isinstance(node, All):
            return lambda v: a(v) and b(v)
        return lambda v: a(v) or b(v)
    # Plain loops, not all()/any() over a generator: a third cheaper per tick.
    if isinstance(node, All):
        def all_of(v: Sequence[float]) -> bool:
            for p in parts:  # noqa: SIM110 - see above
                if not p(v):
                    return False
            return True
        return all_of

    def any_of(v: Sequence[float]) -> bool:
        for p in parts:  # noqa: SIM110 - see above
            if p(v):
                return True
        return False
    return any_of
