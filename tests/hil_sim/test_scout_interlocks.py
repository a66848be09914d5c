"""Scout's interlocks (SPEC 11) over MCP, through the sim module's inputs (SPEC 12): no fast
driving with the arm out of its stowed pose, no motion into a pressed bumper (latched until
`robot:interlock.reset`). The rules ship in examples/robots/scout.yaml."""

from __future__ import annotations

import re
from collections.abc import Iterator

import pytest

from tests.harness import SCOUT_YAML, SimHarness

#: scout.yaml as it ships, rules included.
YAML = SCOUT_YAML
assert "\ninterlocks:" in YAML, "examples/robots/scout.yaml ships its interlocks"


@pytest.fixture
def scout() -> Iterator[SimHarness]:
    h = SimHarness(YAML, marte=False)
    yield h
    h.close()


def rows(line: str) -> dict[str, str]:
    return dict(re.findall(r"(\w+:\w+\.\w+)=\(([^)]*)\)", line))


def test_the_arm_out_of_its_stowed_pose_limits_driving_to_30(scout: SimHarness) -> None:
    c = scout.connect()
    assert c.ask("base:base.drive=(80,0)") == ""
    assert rows(c.ask("base:base.get=()"))["base:left_wheel.vel"] == "80"
    assert c.ask("arm:shoulder.pos=(60)") == ""
    scout.advance(0.3)
    c.ask("")
    assert "arm_out_slow" in rows(c.ask("robot:robot.get=()"))["robot:interlock.active"]
    assert rows(c.ask("base:base.get=()"))["base:left_wheel.vel"] == "30"
    assert c.ask("base:base.drive=(90,0)") == ""
    assert rows(c.ask("base:base.get=()"))["base:left_wheel.vel"] == "30"
    assert c.ask("arm:arm.stow=()") == ""
    for _ in range(4):
        scout.advance(0.5)
        c.ask("")
    assert c.ask("base:base.drive=(90,0)") == ""
    assert rows(c.ask("base:base.get=()"))["base:left_wheel.vel"] == "90"


def test_a_pressed_bumper_stops_the_base_until_reset(scout: SimHarness) -> None:
    c = scout.connect()
    assert c.ask("base:base.drive=(50,0)") == ""
    assert c.ask("sim:input.set=(base,bumper_right,1)") == ""
    scout.advance(0.2)
    c.ask("")
    base = rows(c.ask("base:base.get=()"))
    assert base["base:left_wheel.vel"] == base["base:right_wheel.vel"] == "0"
    assert c.ask("base:base.drive=(20,0)").startswith("base:base.error=(interlocked,bumper")
    assert c.ask("arm:wrist.pos=(30)") == ""  # the arm is not the base
    assert c.ask("sim:input.clear=(base,bumper_right)") == ""
    scout.advance(0.2)
    c.ask("")
    assert c.ask("base:base.drive=(20,0)").startswith("base:base.error=(interlocked,bumper")
    assert c.ask("robot:interlock.reset=(bumper)") == ""
    assert c.ask("base:base.drive=(20,0)") == ""
