"""From a pad's state and the keys held to the requests a profile asks for: pure functions.

The page sends what it reads (axes, buttons, keys) and the mapping happens here, so one
tested implementation decides what a stick position means. An `Intent` is what the operator
asks for right now; whether any of it is sent is the controller's decision (dead-man, page
freshness, STOP latch), never the mapping's.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

from ramp.mcp.protocol import format_value
from ramp.teleop.profile import DRIVE_KEYS, TURBO_KEY, Binding, Profile


@dataclass(frozen=True)
class PadState:
    """One reading of a gamepad: axes -1..1, each button's value 0..1 and pressed flag."""

    axes: tuple[float, ...] = ()
    values: tuple[float, ...] = ()
    pressed: tuple[bool, ...] = ()

    def is_pressed(self, index: int | None) -> bool:
        return index is not None and index < len(self.pressed) and self.pressed[index]


@dataclass(frozen=True)
class Output:
    """The params one continuous binding asks for now, and whether that is its rest."""

    params: tuple[str, ...]
    at_rest: bool


@dataclass(frozen=True)
class Intent:
    """What the operator asks for at one instant."""

    #: The dead-man is held (or, on the keyboard, a drive key is).
    enable: bool = False
    source: str = ""  # "gamepad", "keyboard" or ""
    #: Continuous bindings: request target -> what it should be sent now.
    outputs: dict[str, Output] = field(default_factory=dict)
    #: Press bindings whose button is down now: (target, params).
    presses: frozenset[tuple[str, tuple[str, ...]]] = frozenset()


IDLE = Intent()


def shape(x: float, deadzone: float, expo: float) -> float:
    """Dead zone, then expo, on -1..1: 0 inside the dead zone, continuous at its edge.

    Outside the dead zone the travel left is rescaled to 0..1 so small motions are still
    possible; expo blends in a cubic, `(1 - e)·x + e·x³`, for finer control near centre.
    """
    if not math.isfinite(x):
        return 0.0
    x = max(-1.0, min(1.0, x))
    mag = abs(x)
    if mag <= deadzone:
        return 0.0
    mag = (mag - deadzone) / (1.0 - deadzone)
    mag = (1.0 - expo) * mag + expo * mag ** 3
    return math.copysign(mag, x)


def drive_params(forward: float, turn: float, scale: float) -> tuple[int, float]:
    """Stick (forward, turn), each -1..1, to `base.drive`'s (speed %, direction °).

    SPEC 2.3: left = s(cos d + sin d), right = s(cos d - sin d), the larger scaled to |s|.
    Arcade mixing asks left = forward + turn, right = forward - turn, so d = atan2(turn,
    forward) and |s| is the larger of the two (at most 1) times the scale. Stick up is
    forward, stick right spins clockwise.
    """
    left, right = forward + turn, forward - turn
    mag = min(1.0, max(abs(left), abs(right)))
    speed = round(100.0 * scale * mag)
    if speed == 0:
        return 0, 0.0
    direction = math.degrees(math.atan2(turn, forward))
    return speed, round(direction, 1)


def _value_params(v: float) -> tuple[str, ...]:
    return (str(round(100.0 * max(-1.0, min(1.0, v)))),)


def _binding_output(b: Binding, pad: PadState, turbo: bool) -> Output | None:
    scale = b.turbo_scale if turbo else b.scale
    if b.stick is not None:
        fwd = shape(b.stick[0].read(pad.axes, pad.values), b.deadzone, b.expo)
        turn = shape(b.stick[1].read(pad.axes, pad.values), b.deadzone, b.expo)
        speed, direction = drive_params(fwd, turn, scale)
        return Output((str(speed), format_value(direction)), speed == 0)
    if b.value is not None:
        raw = b.value.read(pad.axes, pad.values)
        if b.minus is not None:
            raw -= b.minus.read(pad.axes, pad.values)
        v = shape(raw, b.deadzone, b.expo) * scale
        params = _value_params(v)
        return Output(params, params == ("0",))
    return None


def from_pad(profile: Profile, pad: PadState) -> Intent:
    """The intent of a standard-mapping pad under `profile`."""
    if not pad.is_pressed(profile.deadman):
        return IDLE
    turbo = pad.is_pressed(profile.turbo)
    outputs: dict[str, Output] = {}
    presses: set[tuple[str, tuple[str, ...]]] = set()
    for b in profile.bindings:
        if b.press is not None:
            if pad.is_pressed(b.press):
                presses.add((b.request, b.params))
            continue
        out = _binding_output(b, pad, turbo)
        if out is None:
            continue
        prev = outputs.get(b.request)
        # Two bindings on one request: the one away from rest wins (first one on a tie).
        if prev is None or (prev.at_rest and not out.at_rest):
            outputs[b.request] = out
    return Intent(True, "gamepad", outputs, frozenset(presses))


def from_keys(profile: Profile, keys: Iterable[str]) -> Intent:
    """W/S/A/D held drive the keyboard's request; nothing held is no intent at all."""
    kb = profile.keyboard
    held = {k.lower() for k in keys}
    if not kb.request or not held & set(DRIVE_KEYS):
        return IDLE
    turbo = TURBO_KEY in held
    forward = float(("w" in held) - ("s" in held))
    turn = float(("d" in held) - ("a" in held))
    speed_scale = kb.turbo_scale if turbo else kb.speed
    turn_scale = kb.turbo_scale if turbo else kb.turn
    if forward and turn:
        # Both held: an arc. Forward at the speed scale, turning at the turn scale.
        speed, direction = drive_params(forward, turn * turn_scale / max(speed_scale, 1e-9),
                                        speed_scale)
    elif turn:
        speed, direction = drive_params(0.0, turn, turn_scale)
    else:
        speed, direction = drive_params(forward, 0.0, speed_scale)
    out = Output((str(speed), format_value(direction)), speed == 0)
    return Intent(True, "keyboard", {kb.request: out})


def intent_of(profile: Profile, pad: PadState | None, keys: Sequence[str]) -> Intent:
    """The pad's intent when its dead-man is held, else the keyboard's."""
    if pad is not None:
        intent = from_pad(profile, pad)
        if intent.enable:
            return intent
    return from_keys(profile, keys)
