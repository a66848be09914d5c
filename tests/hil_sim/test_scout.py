"""Scout (SPEC 10) on its emulators over MCP: the differential base on emulated ODrive axes
over virtual CAN, the bumpers on the flat floor's walls, and the arm plugin's RC servos."""

from __future__ import annotations

import re
import subprocess
from collections.abc import Iterator

import pytest

from tests import harness
from tests.harness import REPO, SCOUT_YAML, SimHarness


@pytest.fixture
def scout() -> Iterator[SimHarness]:
    h = SimHarness(SCOUT_YAML, marte=False)
    yield h
    h.close()


def rows(line: str) -> dict[str, str]:
    return dict(re.findall(r"(\w+:\w+\.\w+)=\(([^)]*)\)", line))


def chassis(h: SimHarness):  # type: ignore[no-untyped-def]
    return next(p for p in h.backplane.signals.parts if hasattr(p, "heading"))


def test_scout_attaches_both_modules_with_spec_10_names(scout: SimHarness) -> None:
    c = scout.connect()
    assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(base,arm)"
    base = rows(c.ask("base:base.get=()"))
    assert set(base) == {"base:left_wheel.vel", "base:right_wheel.vel",
                         "base:bumper_left.press", "base:bumper_right.press",
                         "base:battery.volt", "base:battery.charge"}
    assert 12.0 < float(base["base:battery.volt"]) < 12.7
    # Scout's 3S pack from its YAML model: a fresh battery reads nearly full, never 0 %.
    assert 90.0 <= float(base["base:battery.charge"]) <= 100.0
    assert "base:battery.property=(charge,float,%)" in c.ask("base:base.describe=()")
    arm = rows(c.ask("arm:arm.get=()"))
    assert arm == {"arm:shoulder.pos": "0.0", "arm:shoulder.target": "0.0",
                   "arm:elbow.pos": "90.0", "arm:elbow.target": "90.0",
                   "arm:wrist.pos": "0.0", "arm:wrist.target": "0.0",
                   "arm:gripper.close": "0", "arm:arm.stowed": "1"}
    described = c.ask("arm:arm.describe=()")
    for part in ("arm:shoulder.function=(pos,float -10..100)", "arm:arm.function=(stow)",
                 "arm:gripper.function=(close,int 0..1)", "arm:arm.property=(stowed,int)",
                 "arm:shoulder.kind=(pos,motion)"):
        assert part in described


def test_base_drive_is_marte_s_mix_on_two_odrive_axes(scout: SimHarness) -> None:
    c = scout.connect()
    x0 = chassis(scout).x
    assert c.ask("base:base.drive=(50,45)") == ""
    base = rows(c.ask("base:base.get=()"))
    assert (base["base:left_wheel.vel"], base["base:right_wheel.vel"]) == ("50", "0")
    assert c.ask("base:base.drive=(60,0)") == ""
    scout.advance(1.0)
    c.ask("")  # heartbeat
    assert chassis(scout).x > x0 + 0.3  # forward, through CAN frames to the emulated ODrives
    emu = scout.backplane.emulated["drive"]
    assert emu.axes[0].input_vel > 0 > emu.axes[1].input_vel  # the mirrored right axis
    assert c.ask("base:base.stop=()") == ""
    scout.advance(0.1)
    assert emu.axes[0].input_vel == emu.axes[1].input_vel == 0.0


def test_joints_move_at_their_speed_limit_within_their_yaml_limits(scout: SimHarness) -> None:
    c = scout.connect()
    assert c.ask("arm:shoulder.pos=(101)") == ("arm:shoulder.error=(bad_params,pos takes one "
                                               "float in -10..100)")
    assert c.ask("arm:shoulder.pos=(60)") == ""
    scout.advance(0.5)
    arm = rows(c.ask("arm:arm.get=()"))
    assert float(arm["arm:shoulder.pos"]) == pytest.approx(30.0, abs=2.0)  # 60 deg/s
    assert arm["arm:shoulder.target"] == "60.0"
    assert arm["arm:arm.stowed"] == "0"
    scout.advance(0.6)
    c.ask("")
    assert rows(c.ask("arm:arm.get=()"))["arm:shoulder.pos"] == "60.0"
    assert c.ask("arm:gripper.close=(1)") == ""
    assert c.ask("arm:arm.stow=()") == ""
    scout.advance(0.6)
    c.ask("")
    scout.advance(0.6)
    arm = rows(c.ask("arm:arm.get=()"))
    assert arm["arm:arm.stowed"] == "1" and arm["arm:gripper.close"] == "1"


def test_a_silent_client_s_arm_move_is_stopped_where_it_is(scout: SimHarness) -> None:
    c = scout.connect()
    assert c.ask("arm:elbow.pos=(-90)") == ""  # 180 deg at 90 deg/s: 2 s
    assert c.ask("base:base.drive=(40,0)") == ""
    scout.advance(1.5)  # silent past the 1 s timeout
    state = rows(c.ask("robot:robot.get=()"))
    assert state["robot:watchdog.state"] == "tripped"
    arm = rows(c.ask("arm:arm.get=()"))
    held = float(arm["arm:elbow.pos"])
    assert -10.0 < held < 10.0  # stopped about 1 s in, not at -90
    assert float(arm["arm:elbow.target"]) == held
    scout.advance(1.0)
    assert rows(c.ask("arm:arm.get=()"))["arm:elbow.pos"] == arm["arm:elbow.pos"]
    assert rows(c.ask("base:base.get=()"))["base:left_wheel.vel"] == "0"


def test_a_bumper_closes_against_a_wall(scout: SimHarness) -> None:
    c: harness.TestClient = scout.connect()
    body = chassis(scout)
    body.place(body.floor.length - 0.25, 1.5, 0.0)
    assert c.ask("base:base.drive=(30,0)") == ""
    scout.advance(0.5)
    base = rows(c.ask("base:base.get=()"))
    assert base["base:bumper_left.press"] == base["base:bumper_right.press"] == "1"


def test_ramp_knows_no_arm() -> None:
    found = subprocess.run(["grep", "-ril", r"shoulder\|gripper", "ramp/"], cwd=REPO,
                           capture_output=True, text=True)
    assert found.stdout == ""


def test_sim_input_set_presses_a_scout_bumper_through_its_sensor_model(
        scout: SimHarness) -> None:
    c = scout.connect()
    assert c.ask("sim:input.set=(base,bumper_left,1)") == ""
    assert c.ask("sim:input.set=(base,battery,10.5)") == ""
    scout.advance(0.1)
    base = rows(c.ask("base:base.get=()"))
    assert base["base:bumper_left.press"] == "1" and base["base:bumper_right.press"] == "0"
    scout.advance(12.0)  # the battery filter (2 s) settles
    c.ask("")
    assert float(rows(c.ask("base:base.get=()"))["base:battery.volt"]) == pytest.approx(
        10.5, abs=0.05)
    assert c.ask("sim:input.clear=(base,bumper_left)") == ""
    scout.advance(0.1)
    assert rows(c.ask("base:base.get=()"))["base:bumper_left.press"] == "0"


def test_sim_bus_unplug_faults_scout_s_can_base_and_plug_brings_it_back(
        scout: SimHarness) -> None:
    c = scout.connect()
    assert c.ask("sim:bus.unplug=(drive)") == ""
    scout.advance(1.0)
    c.ask("")
    assert rows(c.ask("robot:robot.get=()"))["robot:base.state"] == "fault"
    assert rows(c.ask("robot:robot.get=()"))["robot:arm.state"] == "ok"
    assert c.ask("sim:bus.plug=(drive)") == ""
    for _ in range(6):
        scout.advance(0.5)
        c.ask("")
    assert rows(c.ask("robot:robot.get=()"))["robot:base.state"] == "ok"
