"""`describe` publishes each function's kind (README, "Talking to the robot"), from the same
table the router validates against, and the clients use it instead of guessing by names."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from ramp.mcp.describe import build_catalog
from ramp.mcp.messages import Request, Response
from ramp.mcp.protocol import parse_response_line
from ramp.shell.cli import accepted_motion
from ramp.teleop.console import is_motion
from tests.harness import SimHarness

KINDS = {"motion", "stop", "state", "read", "control"}


@pytest.fixture(scope="module")
def marte() -> Iterator[SimHarness]:
    h = SimHarness()
    yield h
    h.close()


def describe(h: SimHarness, module: str) -> list[Response]:
    c = h.connect()
    try:
        return parse_response_line(c.ask(f"{module}:{module}.describe=()").encode())
    finally:
        c.close()


def test_every_function_has_one_kind_the_router_also_enforces(marte: SimHarness) -> None:
    for module in ("robot", "base", "ble"):
        rows = describe(marte, module)
        functions = {(r.device, str(r.values[0])) for r in rows if r.prop == "function"}
        kinds = {(r.device, str(r.values[0])): str(r.values[1]) for r in rows
                 if r.prop == "kind"}
        assert set(kinds) == functions and set(kinds.values()) <= KINDS
        table = (marte.sup.robot.robot if module == "robot"
                 else marte.sup.slots[module].module).functions
        assert kinds == {key: fn.kind for key, fn in table.items()}
    base = {(r.device, str(r.values[0])): str(r.values[1])
            for r in describe(marte, "base") if r.prop == "kind"}
    assert base[("lf_wheel", "vel")] == base[("base", "drive")] == "motion"
    assert base[("user_led", "on")] == "state"
    assert base[("base", "get")] == base[("base", "describe")] == "read"
    assert base[("base", "stop")] == "stop"
    robot = {(r.device, str(r.values[0])): str(r.values[1])
             for r in describe(marte, "robot") if r.prop == "kind"}
    assert robot[("control", "acquire")] == "control"
    assert robot[("watchdog", "timeout")] == robot[("control", "release")] == "state"


def test_function_rows_are_unchanged_by_the_kinds(marte: SimHarness) -> None:
    line = marte.connect().ask("base:base.describe=()")
    assert "base:lf_wheel.function=(vel,int -100..100)" in line
    assert "base:lf_wheel.kind=(vel,motion)" in line
    assert line.startswith("base:base.function=(get)")


def test_clients_read_the_kinds_from_describe(marte: SimHarness) -> None:
    catalog = build_catalog(describe(marte, "robot"),
                            {m: describe(marte, m) for m in ("base", "ble")})
    assert catalog.kind_of("base", "user_led", "on") == "state"
    assert catalog.kind_of("ble", "load", "tare") == "state"
    assert catalog.kind_of("ble", "lift", "extend") == "motion"
    led = Request("base", "user_led", "on", ("1",))
    wheel = Request("base", "lf_wheel", "vel", ("10",))
    # The teleop console needs a stop later only after motion, now known, not guessed:
    assert not is_motion(led, catalog) and is_motion(wheel, catalog)
    assert is_motion(led)  # a robot that publishes no kinds: the old guess, to be safe
    # ramp-shell's hold stops what changed something and was accepted:
    assert accepted_motion([led, wheel, Request("base", "base", "get")], [], catalog) == [
        led, wheel]


def test_a_robot_that_publishes_no_kinds_is_guessed_by_name() -> None:
    rows = parse_response_line(b"arm:arm.function=(get)arm:arm.function=(stop)"
                               b"arm:motor.function=(vel,int -100..100)")
    catalog = build_catalog([], {"arm": rows})
    assert catalog.kind_of("arm", "arm", "get") == "read"
    assert catalog.kind_of("arm", "arm", "stop") == "stop"
    assert catalog.kind_of("arm", "motor", "vel") == "motion"
    assert catalog.function("arm", "motor", "vel") is not None
    assert catalog.function("arm", "motor", "vel").kind == ""  # type: ignore[union-attr]
