"""From stick and buttons to requests: dead zone, expo, turbo, the dead-man, the keyboard."""

from __future__ import annotations

import math

import pytest

from ramp.teleop.mapping import (
    IDLE,
    Output,
    PadState,
    drive_params,
    from_keys,
    from_pad,
    intent_of,
    shape,
)
from ramp.teleop.profile import ProfileLibrary, builtin_profile_dir, parse_profile

DEFAULT = ProfileLibrary([builtin_profile_dir()]).load("default")
LB, RB, A, X, Y, LT, RT = 4, 5, 0, 2, 3, 6, 7


def pad(axes: tuple[float, float, float, float] = (0, 0, 0, 0), **buttons: float) -> PadState:
    values = [0.0] * 17
    for name, v in buttons.items():
        values[{"lb": LB, "rb": RB, "a": A, "x": X, "y": Y, "lt": LT, "rt": RT}[name]] = v
    return PadState(tuple(axes), tuple(values), tuple(v >= 0.5 for v in values))


def test_dead_zone_is_zero_inside_and_continuous_at_its_edge() -> None:
    assert shape(0.1, 0.12, 0.0) == 0.0
    assert shape(-0.12, 0.12, 0.0) == 0.0
    assert shape(0.1201, 0.12, 0.0) == pytest.approx(0.0, abs=1e-3)
    assert shape(1.0, 0.12, 0.0) == 1.0
    assert shape(-1.0, 0.12, 0.0) == -1.0
    assert shape(0.56, 0.12, 0.0) == pytest.approx(0.5)
    assert shape(1.7, 0.1, 0.0) == 1.0  # out-of-range readings are clamped
    assert shape(math.nan, 0.1, 0.0) == 0.0


def test_expo_softens_the_centre_and_keeps_the_ends() -> None:
    assert shape(0.5, 0.0, 1.0) == pytest.approx(0.125)
    assert shape(0.5, 0.0, 0.4) == pytest.approx(0.6 * 0.5 + 0.4 * 0.125)
    assert shape(1.0, 0.0, 0.4) == pytest.approx(1.0)
    assert shape(-0.5, 0.0, 0.4) == -shape(0.5, 0.0, 0.4)


@pytest.mark.parametrize(("forward", "turn", "expected"), [
    (1, 0, (100, 0.0)),       # straight ahead
    (-1, 0, (100, 180.0)),    # straight back
    (0, 1, (100, 90.0)),      # spin clockwise
    (0, -1, (100, -90.0)),
    (1, 1, (100, 45.0)),      # pivot on the right side
    (0, 0, (0, 0.0)),
    (0.5, 0, (50, 0.0)),
])
def test_drive_params_follow_spec_2_3(forward: float, turn: float,
                                      expected: tuple[int, float]) -> None:
    assert drive_params(forward, turn, 1.0) == expected


def test_drive_params_give_the_arcade_mix_through_the_spec_formula() -> None:
    for forward, turn in [(0.6, 0.3), (-0.5, 0.2), (0.05, -0.9)]:
        speed, d = drive_params(forward, turn, 1.0)
        r = math.radians(d)
        left, right = math.cos(r) + math.sin(r), math.cos(r) - math.sin(r)
        k = speed / 100 / max(abs(left), abs(right))
        assert left * k == pytest.approx(forward + turn, abs=0.02)
        assert right * k == pytest.approx(forward - turn, abs=0.02)


def test_nothing_without_the_dead_man() -> None:
    assert from_pad(DEFAULT, pad((0, -1, 0, 0), rt=1.0, y=1.0)) is IDLE
    assert not IDLE.enable and IDLE.outputs == {}


def test_left_stick_forward_with_lb_drives_forward_at_the_normal_scale() -> None:
    intent = from_pad(DEFAULT, pad((0, -1, 0, 0), lb=1))
    assert intent.enable and intent.source == "gamepad"
    assert intent.outputs["base:base.drive"] == Output(("50", "0.0"), False)
    assert intent.outputs["ble:chain.vel"] == Output(("0",), True)


def test_turbo_uses_the_turbo_scale() -> None:
    intent = from_pad(DEFAULT, pad((0, -1, 0, 0), lb=1, rb=1))
    assert intent.outputs["base:base.drive"].params == ("100", "0.0")


def test_stick_right_spins_clockwise_and_back_is_180() -> None:
    assert from_pad(DEFAULT, pad((1, 0, 0, 0), lb=1)).outputs["base:base.drive"].params == \
        ("50", "90.0")
    assert from_pad(DEFAULT, pad((0, 1, 0, 0), lb=1)).outputs["base:base.drive"].params == \
        ("50", "180.0")


def test_stick_in_its_dead_zone_is_at_rest() -> None:
    out = from_pad(DEFAULT, pad((0.05, -0.1, 0, 0), lb=1)).outputs["base:base.drive"]
    assert out == Output(("0", "0.0"), True)


def test_triggers_run_the_chain_forward_and_back() -> None:
    assert from_pad(DEFAULT, pad(lb=1, rt=1.0)).outputs["ble:chain.vel"].params == ("100",)
    assert from_pad(DEFAULT, pad(lb=1, lt=1.0)).outputs["ble:chain.vel"].params == ("-100",)
    half = from_pad(DEFAULT, pad(lb=1, rt=0.525)).outputs["ble:chain.vel"].params
    assert half == ("50",)  # (0.525 - 0.05) / 0.95


def test_buttons_held_are_presses_with_their_params() -> None:
    intent = from_pad(DEFAULT, pad(lb=1, x=1, y=1))
    assert intent.presses == {("ble:lift.pos", ("0.5",)), ("ble:lift.extend", ())}


def test_two_bindings_on_one_request_the_moving_one_wins() -> None:
    text = """\
bindings:
  - {request: ble:chain.vel, value: {axis: 3, invert: true}}
  - {request: ble:chain.vel, value: {button: 7}}
"""
    p = parse_profile(text, "t.yaml", "t")
    assert from_pad(p, pad(lb=1, rt=1.0)).outputs["ble:chain.vel"].params == ("100",)
    assert from_pad(p, pad((0, 0, 0, -1), lb=1)).outputs["ble:chain.vel"].params == ("100",)


def test_keys_drive_while_held_and_shift_is_turbo() -> None:
    assert from_keys(DEFAULT, []) is IDLE
    assert from_keys(DEFAULT, ["shift"]) is IDLE
    w = from_keys(DEFAULT, ["w"])
    assert w.enable and w.source == "keyboard"
    assert w.outputs == {"base:base.drive": Output(("50", "0.0"), False)}
    assert from_keys(DEFAULT, ["W", "shift"]).outputs["base:base.drive"].params == ("100", "0.0")
    assert from_keys(DEFAULT, ["s"]).outputs["base:base.drive"].params == ("50", "180.0")
    assert from_keys(DEFAULT, ["a"]).outputs["base:base.drive"].params == ("50", "-90.0")
    assert from_keys(DEFAULT, ["w", "d"]).outputs["base:base.drive"].params == ("50", "45.0")
    assert from_keys(DEFAULT, ["w", "s"]).outputs["base:base.drive"].at_rest


def test_the_pad_wins_while_its_dead_man_is_held() -> None:
    assert intent_of(DEFAULT, pad((0, -1, 0, 0), lb=1), ["s"]).source == "gamepad"
    assert intent_of(DEFAULT, pad((0, -1, 0, 0)), ["s"]).source == "keyboard"
    assert intent_of(DEFAULT, None, []) is IDLE
