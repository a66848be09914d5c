"""The `when` grammar of interlock rules (SPEC 11): parsing, printing, evaluating, refusing."""

from __future__ import annotations

import builtins
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ramp.layers.robot_distribution.condition import (
    MAX_DEPTH,
    All,
    AnyOf,
    Compare,
    ConditionError,
    Node,
    Not,
    compile_condition,
    parse_condition,
    properties,
)

LIFT = "ble:lift.pos"
LB = "base:l_button.press"
RB = "base:r_button.press"


def test_a_comparison_is_a_property_an_operator_and_a_number() -> None:
    assert parse_condition("ble:lift.pos < 0.2") == Compare(LIFT, "<", 0.2)
    assert parse_condition("ble:lift.pos<0.2") == Compare(LIFT, "<", 0.2)
    for op in ("<", "<=", ">", ">=", "==", "!="):
        assert parse_condition(f"{LIFT} {op} -1e2") == Compare(LIFT, op, -100.0)


def test_a_number_first_is_read_as_the_mirrored_comparison() -> None:
    assert parse_condition("0.2 > ble:lift.pos") == Compare(LIFT, "<", 0.2)
    assert parse_condition("1 <= ble:lift.pos") == Compare(LIFT, ">=", 1.0)


def test_not_binds_tighter_than_and_which_binds_tighter_than_or() -> None:
    a, b, c = (Compare(p, "==", 1.0) for p in (LB, RB, "base:user_led.on"))
    text = f"{LB} == 1 or {RB} == 1 and not base:user_led.on == 1"
    assert parse_condition(text) == AnyOf((a, All((b, Not(c)))))
    text = f"({LB} == 1 or {RB} == 1) and base:user_led.on == 1"
    assert parse_condition(text) == All((AnyOf((a, b)), c))
    assert parse_condition(f"not not {LB} == 1") == Not(Not(a))


@pytest.mark.parametrize(("text", "column", "words"), [
    ("", 0, "empty condition"),
    ("   ", 0, "empty condition"),
    ("ble:lift.pos", 13, "expected one of < <= > >= == !="),
    ("ble:lift.pos <", 15, "expected a number"),
    ("ble:lift.pos < ble:lift.vel", 16, "between a property and a number"),
    ("1 < 2", 5, "expected a property"),
    ("ble:lift.pos = 1", 14, "compare with =="),
    ("ble:lift.pos < 1 && base:l_button.press == 1", 18, "use and, or, not"),
    ("(ble:lift.pos < 1", 18, "expected ')'"),
    ("ble:lift.pos < 1)", 17, "unexpected ')'"),
    ("ble:lift.pos < 1 and", 21, "expected a comparison"),
    ("ble:lift.pos < 1 xor ble:lift.pos > 2", 18, "unexpected 'xor'"),
    ("lift.pos < 1", 1, "expected a property"),
    ("ble.lift.pos < 1", 1, "expected a property"),
    ("ble:lift < 1", 1, "expected a property"),
    ("ble:lift.pos < 1e999", 16, "not a finite number"),
    ("ble:lift.pos < nan", 16, "expected a number"),
    ("__import__('os').system('true')", 12, "unexpected character"),
    ("ble:lift.pos < 0x10", 16, "unexpected"),
    ("ble:lift.pos < 1 é", 18, "unexpected character"),
])
def test_what_is_not_a_condition_is_an_error_at_its_column(text: str, column: int,
                                                           words: str) -> None:
    with pytest.raises(ConditionError) as err:
        parse_condition(text)
    assert err.value.column == column, str(err.value)
    assert words in str(err.value)


def test_nesting_and_length_are_bounded_so_the_parser_never_recurses_deep() -> None:
    deep = "(" * (MAX_DEPTH + 1) + f"{LIFT} < 1" + ")" * (MAX_DEPTH + 1)
    with pytest.raises(ConditionError, match="nested deeper"):
        parse_condition(deep)
    with pytest.raises(ConditionError, match="nested deeper"):
        parse_condition("not " * (MAX_DEPTH + 1) + f"{LIFT} < 1")
    ok = "(" * MAX_DEPTH + f"{LIFT} < 1" + ")" * MAX_DEPTH
    assert parse_condition(ok) == Compare(LIFT, "<", 1.0)
    with pytest.raises(ConditionError, match="longer than"):
        parse_condition(" or ".join([f"{LIFT} < 1"] * 1000))


def test_a_compiled_condition_reads_the_values_of_its_properties() -> None:
    node = parse_condition(f"{LB} == 1 or {RB} == 1 and not {LIFT} > 0.5")
    props = properties(node)
    assert props == [LB, RB, LIFT]
    pred = compile_condition(node, {p: i for i, p in enumerate(props)})
    assert pred([1, 0, 0.9])
    assert pred([0, 1, 0.1])
    assert not pred([0, 1, 0.9])
    assert not pred([0, 0, 0.1])


# -- property-based: printed trees read back the same; any text parses or is refused --------

_NAME = st.text("abcxyz_019", min_size=1, max_size=6)
_PROP = st.builds(lambda m, d, p: f"{m}:{d}.{p}", _NAME, _NAME, _NAME)
_NUMBER = st.floats(allow_nan=False, allow_infinity=False)
_COMPARE = st.builds(Compare, _PROP, st.sampled_from(["<", "<=", ">", ">=", "==", "!="]),
                     _NUMBER)


def _trees(children: Any) -> Any:
    return st.one_of(
        st.builds(Not, children),
        st.builds(All, st.lists(children, min_size=2, max_size=4).map(tuple)),
        st.builds(AnyOf, st.lists(children, min_size=2, max_size=4).map(tuple)))


TREES = st.recursive(_COMPARE, _trees, max_leaves=12)


@settings(max_examples=200, deadline=None)
@given(TREES)
def test_a_printed_condition_parses_back_to_the_same_tree(tree: Node) -> None:
    assert parse_condition(str(tree)) == tree


@settings(max_examples=100, deadline=None)
@given(TREES, st.data())
def test_the_compiled_predicate_agrees_with_the_tree(tree: Node, data: st.DataObject) -> None:
    props = properties(tree)
    values = [data.draw(_NUMBER) for _ in props]
    pred = compile_condition(tree, {p: i for i, p in enumerate(props)})
    assert pred(values) == _truth(tree, dict(zip(props, values, strict=True)))


def _truth(node: Node, values: dict[str, float]) -> bool:
    if isinstance(node, Compare):
        v, k = values[node.prop], node.value
        return {"<": v < k, "<=": v <= k, ">": v > k, ">=": v >= k, "==": v == k,
                "!=": v != k}[node.op]
    if isinstance(node, Not):
        return not _truth(node.arg, values)
    results = [_truth(a, values) for a in node.args]
    return all(results) if isinstance(node, All) else any(results)


_PIECES = st.sampled_from(["ble:lift.pos", "<", "<=", "==", "!=", ">", "0.2", "-1", "1e3",
                           "and", "or", "not", "(", ")", " ", "__import__", "'os'", ".",
                           ":", "=", "lambda", "eval", "exec", ";", "\\", "\n", "\x00"])


def _forbidden(*args: Any, **kwargs: Any) -> Any:
    raise AssertionError("the condition parser must never run code")


@settings(max_examples=500, deadline=None)
@given(st.one_of(st.text(max_size=80), st.lists(_PIECES, max_size=20).map("".join)))
def test_any_text_parses_or_is_a_condition_error_and_never_runs_code(
        text: str) -> None:
    saved = builtins.eval, builtins.exec, builtins.compile, builtins.__import__
    builtins.eval = builtins.exec = builtins.compile = _forbidden  # type: ignore[assignment]
    try:
        try:
            tree = parse_condition(text)
        except ConditionError:
            return
    finally:
        builtins.eval, builtins.exec, builtins.compile, _ = saved
    assert parse_condition(str(tree)) == tree
