"""The `sim` module (SPEC 12) over MCP: faults and inputs injected into the simulated robot,
seen through the real backend's paths (stall detection, hot plug, input readings)."""

from __future__ import annotations

import math
import socket

import pytest

from tests.harness import Harness, SimHarness, value
from tests.harness import TestClient as Client
from tests.harness import ask_line as ask
from tests.harness import start_ramp as start


@pytest.fixture
def h() -> SimHarness:
    harness = SimHarness()
    yield harness
    harness.close()


def fed(h: SimHarness, c: Client, seconds: float) -> None:
    """Let `seconds` pass while `c` keeps its watchdog fed."""
    for _ in range(round(seconds / 0.1)):
        h.advance(0.1)
        assert c.ask("") == ""


def test_describe_lists_every_request_as_kind_state(h: SimHarness) -> None:
    c = h.connect()
    d = c.ask("sim:sim.describe=()")
    for fn in ("lift.function=(jam,int 0..1)", "bus.function=(unplug,name)",
               "bus.function=(plug,name)", "input.function=(set,name,name,float -1000..1000)",
               "input.function=(clear,name,name)"):
        assert f"sim:{fn}" in d
    for dev, fn in (("lift", "jam"), ("bus", "unplug"), ("bus", "plug"), ("input", "set"),
                    ("input", "clear")):
        assert f"sim:{dev}.kind=({fn},state)" in d
    # Not a robot module: robot.modules and robot.get are as on the real robot.
    assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(base,ble)"
    assert "sim" not in c.ask("robot:robot.get=()")


def test_absent_without_sim() -> None:
    h = Harness()
    try:
        c = h.connect()
        assert c.ask("sim:sim.describe=()").startswith("sim:sim.error=(unknown_module,")
        assert c.ask("sim:lift.jam=(1)").startswith("sim:lift.error=(unknown_module,")
    finally:
        h.close()


def test_lift_jam_latches_the_real_stall_detection(h: SimHarness) -> None:
    c = h.connect()
    assert c.ask("sim:lift.jam=(1)") == ""
    assert value(c.ask("sim:sim.get=()"), "sim:lift.jam") == "1"
    assert c.ask("ble:lift.vel=(100)") == ""
    fed(h, c, 2.5)
    get = c.ask("ble:ble.get=()")
    assert value(get, "ble:lift.stalled") == "1"
    assert value(get, "ble:lift.vel") == "0"
    assert h.world.lift_pos == pytest.approx(0.0, abs=1e-6)
    assert h.world.duty("ble.lift_motor") == 0.0


def test_unplug_and_plug_a_serial_bus_goes_through_hot_plug(h: SimHarness) -> None:
    c = h.connect()
    assert c.ask("sim:bus.unplug=(ble_motors)") == ""
    h.advance(0.1)
    get = c.ask("robot:robot.get=()")
    assert "robot:ble.state=(fault)" in get and "robot:base.state=(ok)" in get
    # why, beside the state; a module that is ok has no reason row
    assert "robot:ble.reason=(bus ble_motors: " in get, get
    reason = get.split("robot:ble.reason=(")[1].split(")")[0]
    assert "robot:access.me=" in get.split("robot:ble.reason=(")[1], "a ( or ) in the reason"
    assert "," not in reason
    assert "robot:base.reason" not in get
    assert c.ask("ble:chain.vel=(50)").startswith("ble:chain.error=(fault,")
    assert value(c.ask("sim:sim.get=()"), "sim:bus.unplugged") == "1"
    assert c.ask("sim:bus.plug=(ble_motors)") == ""
    h.advance(2.1)  # the driver retries about once a second
    get = c.ask("robot:robot.get=()")
    assert "robot:ble.state=(ok)" in get and "robot:ble.reason" not in get
    assert c.ask("ble:chain.vel=(50)") == ""


def test_unplug_a_phidget_bus_faults_its_modules_until_plugged(h: SimHarness) -> None:
    c = h.connect()
    assert c.ask("sim:bus.unplug=(sbc_io)") == ""
    h.advance(0.1)
    assert "robot:base.state=(fault)" in c.ask("robot:robot.get=()")
    assert c.ask("sim:bus.plug=(sbc_io)") == ""
    h.advance(2.1)
    assert "robot:base.state=(ok)" in c.ask("robot:robot.get=()")


def test_input_set_and_clear_through_the_sensor_model(h: SimHarness) -> None:
    c = h.connect()
    h.advance(1.0)
    normal = float(value(c.ask("base:base.get=()"), "base:battery.volt"))
    assert normal > 15.0
    assert c.ask("sim:input.set=(base,battery,10.5)sim:input.set=(base,l_button,1)") == ""
    h.advance(12.0)  # the battery filter's time constant is 2 s
    get = c.ask("base:base.get=()")
    assert float(value(get, "base:battery.volt")) == pytest.approx(10.5, abs=0.05)
    assert value(get, "base:l_button.press") == "1"
    assert value(c.ask("sim:sim.get=()"), "sim:input.overrides") == "2"
    assert c.ask("sim:input.clear=(base,battery)sim:input.clear=(base,l_button)") == ""
    h.advance(12.0)
    get = c.ask("base:base.get=()")
    assert float(value(get, "base:battery.volt")) == pytest.approx(normal, abs=0.3)
    assert value(get, "base:l_button.press") == "0"


def test_input_set_on_the_lift_pot_is_a_position(h: SimHarness) -> None:
    c = h.connect()
    assert c.ask("sim:input.set=(ble,lift_pot,0.5)") == ""
    h.advance(0.1)
    assert float(value(c.ask("ble:ble.get=()"), "ble:lift.pos")) == pytest.approx(0.5, abs=1e-3)


@pytest.mark.parametrize(("request_", "detail"), [
    ("sim:bus.unplug=(nope)", "no bus nope; buses: base_motors ble_motors sbc_io"),
    ("sim:bus.plug=(nope)", "no bus nope"),
    ("sim:input.set=(arm,battery,1)", "no module arm; modules: base ble"),
    ("sim:input.set=(base,nope,1)", "base has no device nope; its inputs: battery l_button"),
    ("sim:input.set=(base,lf_wheel,1)", "base:lf_wheel is a motor not an input"),
    ("sim:input.set=(base,l_button,0.5)", "base:l_button is a digital input"),
    ("sim:input.clear=(ble,lift_motor)", "ble:lift_motor is a motor not an input"),
    ("sim:input.set=(base,battery,nan)", "set takes three parameters"),
    ("sim:input.set=(base,battery,1e308)", "set takes three parameters"),
    ("sim:lift.jam=(2)", "jam takes one int in 0..1"),
])
def test_bad_arguments_are_bad_params_and_change_nothing(h: SimHarness, request_: str,
                                                         detail: str) -> None:
    c = h.connect()
    before = c.ask("sim:sim.get=()")
    module, device = request_.split(".")[0].split(":")
    answer = c.ask(request_)
    assert answer.startswith(f"{module}:{device}.error=(bad_params,"), answer
    assert detail in answer
    assert c.ask("sim:sim.get=()") == before
    assert "robot:base.state=(ok)robot:ble.state=(ok)" in c.ask("robot:robot.get=()")


def test_real_buses_cannot_be_unplugged() -> None:
    from tests.harness import MARTE_YAML

    text = MARTE_YAML.replace("ble_bridge: {driver: phidget, serial: 300002}",
                              "ble_bridge: {driver: phidget, serial: 300002, sim: false}")
    h = SimHarness(text)
    try:
        c = h.connect()
        answer = c.ask("sim:bus.unplug=(ble_bridge)")
        assert answer.startswith("sim:bus.error=(bad_params,bus ble_bridge keeps its real")
        assert c.ask("sim:input.set=(ble,load_cell,3)").startswith("sim:input.error=(bad_params")
    finally:
        h.close()


def test_exempt_from_control_arbitration(h: SimHarness) -> None:
    """SPEC 12 (issue 33 item 6): `sim:` acts on the world, not the robot, so a trainer
    injects a fault while someone else (the autonomy) holds control. Before: `not_owner`."""
    owner, other = h.connect(), h.connect()
    assert owner.ask("robot:control.acquire=(autonomy)") == ""
    assert other.ask("sim:lift.jam=(1)") == ""
    assert h.world.lift_jammed
    assert value(other.ask("sim:sim.get=()"), "sim:lift.jam") == "1"
    assert other.ask("sim:bus.unplug=(ble_motors)") == ""
    assert value(owner.ask("robot:robot.get=()"), "robot:control.owner") == "autonomy"
    # the robot itself stays the owner's: a motion request from the trainer is refused
    assert other.ask("base:base.drive=(30,0)").startswith("base:base.error=(not_owner,")


def test_recorded_like_any_request() -> None:
    from ramp.runtime.observers import Observer

    seen: list[bytes] = []

    class Watch(Observer):
        def message_in(self, t: float, client: object, message: object) -> None:
            if isinstance(message, bytes):
                seen.append(message)

    h = SimHarness(observer=Watch())
    try:
        c = h.connect()
        assert c.ask("sim:lift.jam=(1)") == ""
        assert b"sim:lift.jam=(1)" in seen
    finally:
        h.close()


def test_mission_adds_lidar_blind_and_imu_shift() -> None:
    from firmware_like.marte import MarteWorld
    from ramp.layers.robot_distribution import Client
    from ramp.simulation.backend import SimBackend
    from ramp.simulation.rig import Rig

    world = MarteWorld()
    backend = SimBackend(world)
    with Rig(world, seed=0, backend=backend) as rig:
        client = Client("trainer")

        def ask_(text: str) -> str:
            return backend.supervisor.server.answer_message(client, text.encode()).decode()

        d = ask_("sim:sim.describe=()")
        assert "sim:lidar.function=(blind,int 0..1)" in d
        assert "sim:imu.function=(shift,float -90..90)" in d
        seen: list[int] = []
        rig.scans.add_listener(lambda rec: seen.append(int(
            sum(1 for r in rec.ranges if not math.isnan(r)))))
        rig.run_for(0.5)
        assert seen and max(seen) > 100  # the arena's walls
        assert ask_("sim:lidar.blind=(1)sim:imu.shift=(6)") == "\n"
        seen.clear()
        rig.run_for(0.5)
        assert seen and max(seen[2:]) == 0  # every beam returns nothing
        assert rig.imu_emulator.shift_fraction(rig.clock.now()) == 1.0
        assert "sim:imu.shift=(6.0)" in ask_("sim:sim.get=()")
        assert ask_("sim:imu.shift=(91)").startswith("sim:imu.error=(bad_params,")
        assert ask_("sim:lidar.blind=(0)") == "\n"
        seen.clear()
        rig.run_for(0.5)
        assert max(seen[2:]) > 100


def test_ramp_run_sim_serves_the_sim_module() -> None:
    proc, host, port = start(["--sim", "--host", "127.0.0.1", "--port", "0"])
    try:
        with socket.create_connection((host, port), timeout=5) as s:
            assert "sim:bus.function=(unplug,name)" in ask(s, "sim:sim.describe=()")
            assert ask(s, "sim:input.set=(base,r_button,1)") == ""
            assert ask(s, "sim:input.set=(base,x,1)").startswith(
                "sim:input.error=(bad_params,base has no device x")
    finally:
        proc.terminate()
        proc.communicate(timeout=10)


def test_unplug_a_can_bus_silences_the_odrives_until_plugged() -> None:
    """MARTE on ODrives (examples/marte-odrive.yaml): the axes fall silent on the CAN bus,
    the driver's stale-heartbeat check faults the Base, and it comes back after plug."""
    from tests.harness import REPO

    h = SimHarness((REPO / "examples" / "marte-odrive.yaml").read_text())
    try:
        c = h.connect()
        assert "robot:base.state=(ok)" in c.ask("robot:robot.get=()")
        assert c.ask("sim:bus.unplug=(base_motors)") == ""
        h.advance(1.5)
        assert "robot:base.state=(fault)" in c.ask("robot:robot.get=()")
        assert c.ask("sim:bus.plug=(base_motors)") == ""
        h.advance(3.0)
        assert "robot:base.state=(ok)" in c.ask("robot:robot.get=()")
        assert c.ask("base:base.drive=(30,0)") == ""
    finally:
        h.close()


def test_sim_is_a_reserved_module_name() -> None:
    from ramp.config import parse_config

    text = "buses:\n  io: {driver: sim}\nmodules:\n  sim: {type: demo, motor: {bus: io}, " \
           "lamp: {bus: io}}\n"
    _, errors = parse_config(text, "robot.yaml")
    assert [str(e) for e in errors] == [
        "robot.yaml:4: modules.sim: `sim` is reserved for the simulator's fault injection "
        "(SPEC 12, under --sim)"]
