"""MARTE over MCP against the simulated robot: tables 5.3-5.6 end to end (issue: modules)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.harness import SimHarness


@pytest.fixture
def h() -> SimHarness:
    harness = SimHarness()
    yield harness
    harness.close()


def values(resp: str, key: str) -> list[str]:
    m = re.search(re.escape(key) + r"=\(([^)]*)\)", resp)
    assert m, f"{key} not in {resp}"
    return m.group(1).split(",")


def num(resp: str, key: str) -> float:
    return float(values(resp, key)[0])


def drive(h: SimHarness, c, request: str, seconds: float) -> None:
    """Send a motion request and keep the watchdog fed for `seconds` of simulated time."""
    assert c.ask(request) == ""
    for _ in range(int(seconds / 0.1)):
        h.advance(0.1)
        assert c.ask("") == ""


def test_modules_attached_and_get_rows_complete(h: SimHarness) -> None:
    c = h.connect()
    assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
    base = c.ask("base:base.get=()")
    for key in ("base:lf_wheel.vel", "base:lb_wheel.vel", "base:rf_wheel.vel",
                "base:rb_wheel.vel", "base:l_button.press", "base:r_button.press",
                "base:battery.volt", "base:user_led.on"):
        assert key + "=(" in base
    ble = c.ask("ble:ble.get=()")
    for key in ("ble:lift.vel", "ble:lift.pos", "ble:chain.vel", "ble:load.kg"):
        assert key + "=(" in ble


def test_drive_forward_moves_the_chassis_forward(h: SimHarness) -> None:
    h.world.place(2.0, 1.94, 0.0)
    c = h.connect()
    drive(h, c, "base:base.drive=(100,0)", 2.0)
    assert values(c.ask("base:base.get=()"), "base:lf_wheel.vel") == ["100"]
    assert h.world.x > 2.3
    assert abs(h.world.y - 1.94) < 0.05
    assert abs(h.world.heading_deg) < 3


def test_spin_turns_in_place(h: SimHarness) -> None:
    h.world.place(3.0, 1.94, 0.0)
    c = h.connect()
    drive(h, c, "base:base.drive=(100,90)", 2.0)
    assert abs(h.world.x - 3.0) < 0.1
    assert h.world.heading_deg < -20  # clockwise: yaw decreases (SPEC 2.3, 6.1)


def test_single_wheel_and_stop(h: SimHarness) -> None:
    c = h.connect()
    assert c.ask("base:rf_wheel.vel=(-40)") == ""
    h.advance(0.2)
    get = c.ask("base:base.get=()")
    assert values(get, "base:rf_wheel.vel") == ["-40"]
    assert h.world.wheel_speed("base.rf_wheel") < 0
    assert c.ask("base:base.stop=()") == ""
    assert values(c.ask("base:base.get=()"), "base:rf_wheel.vel") == ["0"]


def test_user_led_and_errors(h: SimHarness) -> None:
    c = h.connect()
    assert c.ask("base:user_led.on=(1)") == ""
    h.advance(0.05)
    assert values(c.ask("base:base.get=()"), "base:user_led.on") == ["1"]
    assert h.world.output("base.user_led") is True
    assert c.ask("base:user_led.on=(2)").startswith("base:user_led.error=(bad_params,")
    assert c.ask("base:lf_wheel.vel=(101)").startswith("base:lf_wheel.error=(bad_params,")
    assert c.ask("base:base.drive=(50)").startswith("base:base.error=(bad_params,")
    assert c.ask("base:base.drive=(50,inf)").startswith("base:base.error=(bad_params,")
    assert c.ask("ble:lift.pos=(1.5)").startswith("ble:lift.error=(bad_params,")


def test_battery_reads_lower_under_load(h: SimHarness) -> None:
    c = h.connect()
    h.advance(5.0)
    rest = num(c.ask("base:base.get=()"), "base:battery.volt")
    assert 17.0 < rest < 21.5
    # MARTE's 5S model (ramp.yaml): fresh packs in the sim read well charged.
    assert 80.0 <= num(c.ask("base:base.get=()"), "base:battery.charge") <= 100.0
    h.world.place(1.0, 1.94, 0.0)
    drive(h, c, "base:base.drive=(100,90)ble:chain.vel=(100)", 6.0)
    loaded = num(c.ask("base:base.get=()"), "base:battery.volt")
    assert loaded < rest - 0.3


def test_lift_moves_to_position_and_holds(h: SimHarness) -> None:
    c = h.connect()
    drive(h, c, "ble:lift.pos=(0.5)", 8.0)
    pos = num(c.ask("ble:ble.get=()"), "ble:lift.pos")
    assert abs(pos - 0.5) <= 0.03
    assert abs(h.world.lift_pos - 0.5) <= 0.035
    drive(h, c, "ble:lift.retract=()", 7.0)
    get = c.ask("ble:ble.get=()")
    assert num(get, "ble:lift.pos") <= 0.02
    assert values(get, "ble:lift.vel") == ["0"]


def test_dig_in_the_digging_region_fills_the_bin(h: SimHarness) -> None:
    h.world.place(5.5, 1.94, 0.0)
    c = h.connect()
    drive(h, c, "ble:lift.retract=()", 1.0)
    before = num(c.ask("ble:ble.get=()"), "ble:load.kg")
    drive(h, c, "ble:chain.vel=(100)", 10.0)
    after = num(c.ask("ble:ble.get=()"), "ble:load.kg")
    assert after > before + 1.5
    assert h.world.bin_kg > 1.5


def test_no_digging_outside_the_digging_region(h: SimHarness) -> None:
    h.world.place(0.9, 1.94, 0.0)
    c = h.connect()
    drive(h, c, "ble:chain.vel=(100)", 5.0)
    assert h.world.bin_kg == pytest.approx(0.0, abs=0.01)


def test_raising_the_lift_over_the_collector_empties_the_bin(h: SimHarness) -> None:
    h.world.place(5.5, 1.94, 0.0)
    c = h.connect()
    drive(h, c, "ble:chain.vel=(100)", 10.0)
    c.ask("ble:chain.vel=(0)")
    loaded = num(c.ask("ble:ble.get=()"), "ble:load.kg")
    assert loaded > 1.5
    # Back at the collector wall (rear touching x = 0), then raise the bin.
    h.world.place(0.62, 1.94, 0.0)
    drive(h, c, "base:base.drive=(-40,0)", 1.5)
    get = c.ask("base:base.get=()")
    assert values(get, "base:l_button.press") == ["1"]
    assert values(get, "base:r_button.press") == ["1"]
    c.ask("base:base.stop=()")
    drive(h, c, "ble:lift.extend=()", 14.0)
    assert num(c.ask("ble:ble.get=()"), "ble:load.kg") < 0.5
    assert h.world.delivered_kg > 1.5


def test_polarity_flip_is_a_yaml_edit() -> None:
    from tests.harness import MARTE_YAML

    flipped = MARTE_YAML.replace(
        "lf_wheel: {bus: base_motors, address: 128, motor: 1}",
        "lf_wheel: {bus: base_motors, address: 128, motor: 1, polarity: -1}")
    assert flipped != MARTE_YAML
    h = SimHarness(flipped)
    try:
        c = h.connect()
        assert c.ask("base:lf_wheel.vel=(50)") == ""
        h.advance(0.5)
        assert h.world.wheel_speed("base.lf_wheel") < 0  # same request, wheel turns backward
        assert values(c.ask("base:base.get=()"), "base:lf_wheel.vel") == ["50"]
    finally:
        h.close()


def test_describe_is_built_from_the_tables(h: SimHarness) -> None:
    c = h.connect()
    base = c.ask("base:base.describe=()")
    assert "base:lf_wheel.function=(vel,int -100..100)" in base
    assert "base:base.function=(drive,int -100..100,float)" in base
    assert "base:battery.property=(volt,float,V)" in base
    ble = c.ask("ble:ble.describe=()")
    assert "ble:lift.function=(pos,float 0..1)" in ble


ODRIVE_YAML = (Path(__file__).resolve().parents[2] / "examples" / "marte-odrive.yaml").read_text()


@pytest.fixture(params=["sabertooth", "odrive"])
def any_drive(request: pytest.FixtureRequest) -> SimHarness:
    """The same drive tests on the Sabertooth wiring and on the ODrive (CAN) wiring."""
    from tests.harness import MARTE_YAML

    harness = SimHarness(MARTE_YAML if request.param == "sabertooth" else ODRIVE_YAML)
    yield harness
    harness.close()


def test_drive_tests_pass_on_either_motor_driver(any_drive: SimHarness) -> None:
    h = any_drive
    h.world.place(2.0, 1.94, 0.0)
    c = h.connect()
    drive(h, c, "base:base.drive=(100,0)", 2.0)
    assert h.world.x > 2.3 and abs(h.world.heading_deg) < 3
    drive(h, c, "base:base.drive=(100,90)", 2.0)
    assert h.world.heading_deg < -20  # clockwise
    drive(h, c, "base:base.drive=(100,180)", 1.0)
    assert c.ask("base:base.stop=()") == ""
    h.advance(0.5)
    assert all(abs(h.world.wheel_speed(f"base.{w}")) < 0.02
               for w in ("lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel"))


def test_a_read_only_device_answers_unknown_function(h: SimHarness) -> None:
    c = h.connect()
    assert c.ask("base:battery.volt=()").startswith(
        "base:battery.error=(unknown_function,battery has no function volt)")
    assert c.ask("base:wheel.vel=(1)").startswith("base:wheel.error=(unknown_device,")


def test_a_base_rate_the_tasks_do_not_divide_still_runs() -> None:
    from tests.harness import MARTE_YAML

    slow = MARTE_YAML.replace("scheduler: {rate_hz: 100}", "scheduler: {rate_hz: 30}")
    assert slow != MARTE_YAML
    h = SimHarness(slow)
    try:
        c = h.connect()
        assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
        drive(h, c, "ble:lift.pos=(0.3)", 5.0)
        assert abs(num(c.ask("ble:ble.get=()"), "ble:lift.pos") - 0.3) <= 0.03
    finally:
        h.close()
