"""Teleop profiles: the default loads, every mistake is named by file:line and key."""

from __future__ import annotations

from pathlib import Path

import pytest

from ramp.teleop.profile import (
    Input,
    ProfileError,
    ProfileLibrary,
    builtin_profile_dir,
    parse_profile,
    user_profile_dir,
)

MINIMAL = """\
bindings:
  - request: base:base.drive
    stick: {forward: {axis: 1, invert: true}, turn: {axis: 0}}
"""


def test_the_default_profile_is_spec_7s() -> None:
    p = ProfileLibrary([builtin_profile_dir()]).load("default")
    assert p.deadman == 4
    drive = next(b for b in p.bindings if b.request == "base:base.drive")
    assert drive.stick == (Input("axis", 1, invert=True), Input("axis", 0))
    chain = next(b for b in p.bindings if b.request == "ble:chain.vel")
    assert chain.value == Input("button", 7)
    assert 0 < drive.deadzone < 0.5 and 0 <= drive.expo <= 1
    assert drive.turbo_scale > drive.scale
    assert {b.request for b in p.bindings if b.press is not None} >= {
        "ble:lift.extend", "ble:lift.retract", "ble:lift.pos"}
    assert p.modules == ("base", "ble")
    rows = p.summary()["rows"]
    assert "dead-man" in rows[0]["does"] and "LB" in rows[0]["input"]


def test_defaults_fill_in_what_a_minimal_profile_leaves_out() -> None:
    p = parse_profile(MINIMAL, "mine.yaml", "mine")
    assert (p.name, p.deadman, p.turbo) == ("mine", 4, 5)
    (b,) = p.bindings
    assert (b.deadzone, b.expo, b.scale, b.turbo_scale) == (0.1, 0.0, 1.0, 1.0)
    assert p.keyboard.request == "base:base.drive"


def test_keyboard_can_be_switched_off() -> None:
    p = parse_profile(MINIMAL + "keyboard: null\n", "mine.yaml", "mine")
    assert p.keyboard.request == ""
    assert p.modules == ("base",)


@pytest.mark.parametrize(("text", "where", "says"), [
    (MINIMAL.replace("axis: 1", "axis: 9"), "mine.yaml:3: bindings.0.stick.forward.axis",
     "9 is not an axis (0-3"),
    (MINIMAL + "    deadzone: 2\n", "mine.yaml:4: bindings.0.deadzone",
     "2 is not a dead zone in 0..0.9"),
    (MINIMAL.replace("base:base.drive", "base.drive"), "mine.yaml:2: bindings.0.request",
     "is not a request target"),
    (MINIMAL + "    spin: 1\n", "mine.yaml:4: bindings.0", "unknown key 'spin'"),
    ("deadman: 4\n", "mine.yaml:1", "missing key 'bindings'"),
    ("deadman: 40\n" + MINIMAL, "mine.yaml:1: deadman", "40 is not a button (0-16"),
    (MINIMAL + "  - {request: ble:lift.extend, press: 4}\n", "mine.yaml:4: bindings.1",
     "already the dead-man"),
    # The dead-man and turbo buttons drive nothing else: holding the dead-man was turbo, and
    # a value on it ran the chain whenever motion was enabled.
    ("deadman: 5\n" + MINIMAL, "mine.yaml:1: deadman", "both the dead-man and the turbo"),
    ("deadman: 3\nturbo: 3\n" + MINIMAL, "mine.yaml:2: turbo", "turbo: null"),
    (MINIMAL + "  - {request: ble:chain.vel, value: {button: 4}}\n",
     "mine.yaml:4: bindings.1.value", "button 4 is already the dead-man button"),
    (MINIMAL + "  - {request: ble:chain.vel, value: {button: 7}, minus: {button: 5}}\n",
     "mine.yaml:4: bindings.1.minus", "button 5 is already the turbo button"),
    (MINIMAL.replace("turn: {axis: 0}", "turn: {button: 4}"),
     "mine.yaml:3: bindings.0.stick.turn", "already the dead-man button"),
    (MINIMAL + "  - {request: ble:chain.vel, value: {button: 7}, params: [1]}\n",
     "mine.yaml:4: bindings.1.params", "params go with press"),
    (MINIMAL + "  - {request: ble:chain.vel}\n", "mine.yaml:4: bindings.1",
     "exactly one of stick, value, press"),
    (MINIMAL + "  - {request: ble:chain.vel, value: {axis: 1, button: 2}}\n",
     "mine.yaml:4: bindings.1.value", "exactly one of axis, button"),
    ("bindings: [\n", "mine.yaml:2", "not valid YAML"),
    ("", "mine.yaml:1", "empty"),
    (MINIMAL + "    scale: 0\n", "mine.yaml:4: bindings.0.scale", "never move"),
])
def test_errors_name_file_line_and_key(text: str, where: str, says: str) -> None:
    with pytest.raises(ProfileError) as info:
        parse_profile(text, "mine.yaml", "mine")
    message = str(info.value)
    assert message.startswith(where), message
    assert says in message


def test_the_operators_file_wins_over_the_builtin_one(tmp_path: Path) -> None:
    builtin, user = tmp_path / "builtin", tmp_path / "user"
    builtin.mkdir()
    user.mkdir()
    (builtin / "default.yaml").write_text(MINIMAL)
    (builtin / "other.yaml").write_text(MINIMAL)
    (user / "default.yaml").write_text("deadman: 5\nturbo: null\n" + MINIMAL)
    (user / "zz.yaml").write_text(MINIMAL)
    (user / "not a name!.yaml").write_text(MINIMAL)
    lib = ProfileLibrary([builtin, user])
    assert lib.names() == ["default", "other", "zz"]
    p = lib.load("default")
    assert (p.deadman, p.turbo, p.source) == (5, None, str(user / "default.yaml"))
    with pytest.raises(ProfileError, match="no profile named 'nope' .known: default, other, zz"):
        lib.load("nope")


def test_user_profile_dir_follows_xdg() -> None:
    assert user_profile_dir({"XDG_CONFIG_HOME": "/x"}) == Path("/x/ramp/profiles")
    assert user_profile_dir({"HOME": "/home/op"}) == Path("/home/op/.config/ramp/profiles")
