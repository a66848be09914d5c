"""Typed MCP parameters (ramp/mcp/params.py): what each type accepts, refuses and says."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ramp.mcp.params import (
    BadParam,
    FlagParam,
    FloatParam,
    IntParam,
    NameParam,
    convert_all,
    signature,
)

PROPS = settings(max_examples=200, deadline=None)
VEL = IntParam(-100, 100)


@pytest.mark.parametrize(
    ("token", "value"),
    [("0", 0), ("100", 100), ("-100", -100), ("+5", 5), ("-0", 0), ("007", 7)],
)
def test_int_accepts(token: str, value: int) -> None:
    got = VEL.convert(token)
    assert got == value and type(got) is int


@pytest.mark.parametrize(
    "token",
    ["101", "-101", "5.0", "1e2", "", " 5", "5 ", "0x10", "five", "+", "--5", "1" * 21],
)
def test_int_refuses(token: str) -> None:
    with pytest.raises(BadParam):
        VEL.convert(token)


def test_int_length_guard_allows_any_token_the_parser_can_carry() -> None:
    wide = IntParam(-(10**70), 10**70)
    assert wide.convert("9" * 64) == int("9" * 64)
    assert IntParam(-100, 100).convert("0" * 60 + "100") == 100  # leading zeros: an int
    with pytest.raises(BadParam):
        wide.convert("9" * 65)


def test_bad_param_is_a_value_error() -> None:
    assert issubclass(BadParam, ValueError)


@pytest.mark.parametrize(
    ("token", "value"),
    [("0", 0.0), ("1", 1.0), ("0.5", 0.5), (".5", 0.5), ("1.", 1.0), ("-1", -1.0),
     ("5e-1", 0.5), ("+1E0", 1.0), ("1e-999", 0.0)],
)
def test_float_accepts_int_and_exponent_forms(token: str, value: float) -> None:
    got = FloatParam(-1.0, 1.0).convert(token)
    assert got == value and type(got) is float


@pytest.mark.parametrize(
    "token",
    ["nan", "inf", "-inf", "1e999", "-1e999", "1.0001", "-1.5", ".", "e5", "1e", "1.2.3",
     "", " 0.5", "0,5", "0x1p-1", "1" * 65],
)
def test_float_refuses(token: str) -> None:
    with pytest.raises(BadParam):
        FloatParam(-1.0, 1.0).convert(token)


def test_float_unbounded_takes_any_finite_value() -> None:
    p = FloatParam()
    assert p.convert("-720.5") == -720.5
    assert p.convert("1e300") == 1e300
    with pytest.raises(BadParam):
        p.convert("1e400")


def test_float_open_lower_bound() -> None:
    timeout = FloatParam(0.0, 60.0, lo_open=True)
    with pytest.raises(BadParam):
        timeout.convert("0")
    with pytest.raises(BadParam):
        timeout.convert("-0.0")
    assert timeout.convert("0.001") == 0.001
    assert timeout.convert("60") == 60.0
    with pytest.raises(BadParam):
        timeout.convert("60.0001")


def test_float_bounds_are_inclusive() -> None:
    pos = FloatParam(0.0, 1.0)
    assert pos.convert("0.0") == 0.0
    assert pos.convert("1.0") == 1.0


def test_flag() -> None:
    flag = FlagParam()
    assert flag.convert("0") == 0 and flag.convert("1") == 1
    for bad in ("2", "-1", "true", "01", "+1", "1.0", ""):
        with pytest.raises(BadParam):
            flag.convert(bad)
    assert flag.describe() == "int 0..1"


def test_name() -> None:
    name = NameParam(reserved=("none",))
    assert name.convert("autonomy-1") == "autonomy-1"
    assert name.convert("x" * 32) == "x" * 32
    for bad in ("none", "", "x" * 33, "a b", "a.b", "a+b", "é"):
        with pytest.raises(BadParam):
            name.convert(bad)
    assert name.describe() == "name"


def test_describe() -> None:
    assert VEL.describe() == "int -100..100"
    assert FloatParam().describe() == "float"
    assert FloatParam(0.0, 1.0).describe() == "float 0..1"
    assert FloatParam(-0.5, 2.25).describe() == "float -0.5..2.25"
    assert FloatParam(0.0, 60.0, lo_open=True).describe() == "float >0..60"
    assert FloatParam(lo=0.0).describe() == "float 0.."


def test_convert_all_types_in_order() -> None:
    drive = (VEL, FloatParam())
    assert convert_all(drive, ("50", "-90")) == [50, -90.0]
    assert convert_all((), ()) == []


@pytest.mark.parametrize("tokens", [(), ("50",), ("50", "1", "2")])
def test_convert_all_wrong_count(tokens: tuple[str, ...]) -> None:
    with pytest.raises(BadParam):
        convert_all((VEL, FloatParam()), tokens)


def test_convert_all_bad_token_anywhere() -> None:
    with pytest.raises(BadParam):
        convert_all((VEL, FloatParam()), ("50", "nan"))
    with pytest.raises(BadParam):
        convert_all((VEL, FloatParam()), ("500", "1"))


def test_signature_wording() -> None:
    assert signature("stop", ()) == "stop takes no parameters"
    assert signature("vel", (VEL,)) == "vel takes one int in -100..100"
    assert signature("drive", (VEL, FloatParam())) == (
        "drive takes two parameters: int in -100..100 and float"
    )
    assert signature("pos", (FloatParam(0.0, 1.0),)) == "pos takes one float in 0..1"
    five = (FlagParam(),) * 5
    assert signature("f", five).startswith("f takes 5 parameters: int in 0..1 and ")


@PROPS
@given(st.integers(min_value=-100, max_value=100))
def test_int_round_trips_in_range(v: int) -> None:
    assert VEL.convert(str(v)) == v


@PROPS
@given(st.integers().filter(lambda v: not -100 <= v <= 100))
def test_int_out_of_range_refused(v: int) -> None:
    with pytest.raises(BadParam):
        VEL.convert(str(v))


@PROPS
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_float_accepts_python_repr(x: float) -> None:
    token = repr(x)
    if len(token) <= 64:
        assert FloatParam().convert(token) == x


@PROPS
@given(st.text(max_size=40))
def test_converters_raise_only_bad_param(token: str) -> None:
    for p in (VEL, FloatParam(), FlagParam(), NameParam(("none",))):
        try:
            v = p.convert(token)
        except BadParam:
            continue
        if isinstance(p, FloatParam):
            assert math.isfinite(v)


# Formerly known defects (\d matched non-ASCII digits), fixed in params.py.


def test_int_refuses_non_ascii_digits() -> None:
    with pytest.raises(BadParam):
        VEL.convert("\u0661\u0662")  # Arabic-Indic "12": int() accepts it


def test_float_refuses_non_ascii_digits() -> None:
    with pytest.raises(BadParam):
        FloatParam(0.0, 1.0).convert("\u0660.\u0665")
