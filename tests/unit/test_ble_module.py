"""BleModule: the SPEC 2.1 table, get rows, parameter checks through Module.lookup, the lift
task against a small plant, stall fault through the module, stop, is_moving, tare."""

from __future__ import annotations

import math
from typing import Any

import pytest

from ramp.errors import ConfigError, RequestError
from ramp.hal.interfaces import AnalogInput, BridgeInput, MotorChannel
from ramp.layers.module_distribution import BoundDevice
from ramp.mcp.messages import Request, Response
from ramp.modules.ble import BleModule

V0, V1 = 0.5, 4.5
MOTORS = ("chain_left", "chain_right", "lift_motor")


class FakeMotor(MotorChannel):
    def __init__(self, label: str) -> None:
        super().__init__(None, label)  # type: ignore[arg-type]

    def _apply(self, duty: float) -> None:
        pass


class FakePot(AnalogInput):
    def __init__(self) -> None:
        super().__init__(None, "lift_pot")  # type: ignore[arg-type]
        self.volts = V0

    def read(self) -> float:
        return self.volts


class FakeBridge(BridgeInput):
    def __init__(self) -> None:
        super().__init__(None, "load_cell")  # type: ignore[arg-type]
        self.ratio = 0.0

    def read(self) -> float:
        return self.ratio


class World:
    """The lift plant: 10 s full stroke at full duty, ends at 0 and 1, optionally stuck."""

    def __init__(self, pos: float) -> None:
        self.pos = pos
        self.stuck = False


def build(pos: float = 0.5, settings: dict[str, dict[str, Any]] | None = None,
          **overrides: dict[str, Any]) -> tuple[BleModule, dict[str, Any], World]:
    chans: dict[str, Any] = {n: FakeMotor(n) for n in MOTORS}
    chans["lift_pot"] = FakePot()
    chans["load_cell"] = FakeBridge()
    params: dict[str, dict[str, Any]] = {
        n: {"polarity": 1, "full_duty": 1.0, "deadband": 0.0} for n in MOTORS}
    params["lift_pot"] = {"volts_at_0": V0, "volts_at_1": V1}
    params["load_cell"] = {"kg_per_mv_v": 100.0, "offset_mv_v": 0.0}
    for name, extra in overrides.items():
        params[name].update(extra)
    devices = {n: BoundDevice(ch, params[n]) for n, ch in chans.items()}
    world = World(pos)
    chans["lift_pot"].volts = V0 + pos * (V1 - V0)
    return BleModule("ble", devices, settings or {}), chans, world


def run(m: BleModule, chans: dict[str, Any], world: World, t0: float, seconds: float
        ) -> tuple[float, list[float]]:
    """100 Hz base tick: the plant every tick, the module's tasks at their divisors."""
    tasks = m.tasks()
    duties = []
    t = t0
    for i in range(1, round(seconds * 100) + 1):
        t = t0 + i / 100
        if not world.stuck:
            world.pos = min(1.0, max(0.0, world.pos + chans["lift_motor"].duty * 0.1 / 100))
        chans["lift_pot"].volts = V0 + world.pos * (V1 - V0)
        for task in tasks:
            if i % round(100 / task.rate_hz) == 0:
                task.run(t, 1 / task.rate_hz)
        duties.append(chans["lift_motor"].duty)
    return t, duties


def call(m: BleModule, device: str, function: str, *params: str) -> list[Response] | None:
    fn, values = m.lookup(Request("ble", device, function, params))
    return fn.run(*values)


def rows(m: BleModule) -> dict[str, Any]:
    got = call(m, "ble", "get")
    assert got is not None
    return {f"{r.device}.{r.prop}": r.values[0] for r in got}


def test_device_and_settings_schema() -> None:
    kinds = {n: s.kind for n, s in BleModule.devices.items()}
    assert kinds == {"chain_left": "motor", "chain_right": "motor", "lift_motor": "motor",
                     "lift_pot": "analog_in", "load_cell": "bridge_in"}
    pot = BleModule.devices["lift_pot"].fields
    assert pot["volts_at_0"].required and pot["volts_at_1"].required
    assert set(BleModule.devices["load_cell"].fields) == {"kg_per_mv_v", "offset_mv_v"}
    lift = BleModule.settings["lift"]
    assert lift["tolerance"].default == 0.03
    assert lift["stall_time"].default == 1.5
    assert {"hysteresis", "stall_min_change"} <= set(lift)


def test_function_table_is_spec_2_1_plus_tare_and_reset() -> None:
    m, _, _ = build()
    table = {k: (f.kind, [p.describe() for p in f.params]) for k, f in m.functions.items()}
    assert table == {
        ("ble", "get"): ("read", []),
        ("ble", "stop"): ("stop", []),
        ("ble", "describe"): ("read", []),
        ("lift", "vel"): ("motion", ["int -100..100"]),
        ("lift", "extend"): ("motion", []),
        ("lift", "retract"): ("motion", []),
        ("lift", "pos"): ("motion", ["float 0..1"]),
        ("chain", "vel"): ("motion", ["int -100..100"]),
        ("load", "tare"): ("state", []),
        ("lift", "reset"): ("state", []),
    }


def test_get_rows_in_table_5_6_order() -> None:
    m, chans, _ = build(pos=0.25)
    chans["load_cell"].ratio = 0.2
    got = call(m, "ble", "get")
    assert got is not None
    assert [(r.module, r.device, r.prop) for r in got] == [
        ("ble", "lift", "vel"), ("ble", "lift", "pos"), ("ble", "chain", "vel"),
        ("ble", "load", "kg"), ("ble", "lift", "stalled")]
    vals = [r.values[0] for r in got]
    assert vals[0] == 0 and type(vals[0]) is int
    assert vals[1] == pytest.approx(0.25) and type(vals[1]) is float
    assert vals[2] == 0 and type(vals[2]) is int
    assert vals[3] == pytest.approx(20.0) and type(vals[3]) is float
    assert vals[4] == 0


def test_describe_rows() -> None:
    m, _, _ = build()
    desc = call(m, "ble", "describe")
    assert desc is not None
    assert Response("ble", "lift", "function", ("pos", "float 0..1")) in desc
    assert Response("ble", "lift", "function", ("extend",)) in desc
    assert Response("ble", "load", "property", ("kg", "float", "kg")) in desc
    assert Response("ble", "lift", "property", ("stalled", "int")) in desc


@pytest.mark.parametrize(("device", "function", "params"), [
    ("lift", "vel", ("101",)),
    ("lift", "vel", ("0.5",)),
    ("lift", "pos", ("1.5",)),
    ("lift", "pos", ("-0.1",)),
    ("lift", "pos", ("nan",)),
    ("lift", "pos", ()),
    ("lift", "extend", ("1",)),
    ("lift", "retract", ("0",)),
    ("chain", "vel", ("x",)),
    ("chain", "vel", ("-100", "5")),
    ("load", "tare", ("0",)),
])
def test_bad_params(device: str, function: str, params: tuple[str, ...]) -> None:
    m, chans, _ = build()
    with pytest.raises(RequestError) as e:
        m.lookup(Request("ble", device, function, params))
    assert e.value.code == "bad_params"
    assert all(chans[n].duty == 0.0 for n in MOTORS)


def test_chain_vel_drives_both_motors_and_stop_zeroes_everything() -> None:
    m, chans, world = build(chain_right={"polarity": -1})
    call(m, "chain", "vel", "70")
    assert (chans["chain_left"].duty, chans["chain_right"].duty) == (0.7, -0.7)
    call(m, "lift", "vel", "-40")
    assert chans["lift_motor"].duty == -0.4
    r = rows(m)
    assert (r["chain.vel"], r["lift.vel"]) == (70, -40)
    assert m.is_moving()
    assert call(m, "ble", "stop") is None
    assert [chans[n].duty for n in MOTORS] == [0.0, 0.0, 0.0]
    r = rows(m)
    assert (r["chain.vel"], r["lift.vel"]) == (0, 0)
    assert not m.is_moving()


def test_lift_pos_move_through_the_module() -> None:
    m, chans, world = build(pos=0.1)
    assert call(m, "lift", "pos", "0.6") is None
    assert rows(m)["lift.vel"] == 100  # the controller's output during the move
    assert m.is_moving()
    t, duties = run(m, chans, world, 0.0, 8.0)
    assert abs(world.pos - 0.6) <= 0.03
    assert rows(m)["lift.pos"] == pytest.approx(world.pos)
    assert rows(m)["lift.vel"] == 0
    signs = [d for d in duties if d != 0]
    assert signs and all(d == 1.0 for d in signs)  # one direction, full speed only
    assert m.is_moving()  # holding until stopped
    call(m, "ble", "stop")
    assert not m.is_moving()


def test_extend_and_retract_through_the_module() -> None:
    m, chans, world = build(pos=0.5)
    call(m, "lift", "extend")
    t, _ = run(m, chans, world, 0.0, 6.0)
    r = rows(m)
    assert r["lift.pos"] >= 0.99 and r["lift.vel"] == 0
    assert not m.is_moving()
    call(m, "lift", "retract")
    assert rows(m)["lift.vel"] == -100
    run(m, chans, world, t, 11.0)
    r = rows(m)
    assert r["lift.pos"] <= 0.01 and r["lift.vel"] == 0


def test_stall_fault_through_the_module() -> None:
    m, chans, world = build(pos=0.3, settings={"lift": {"stall_time": 1.0}})
    world.stuck = True
    call(m, "lift", "extend")
    t, _ = run(m, chans, world, 0.0, 1.2)
    r = rows(m)
    assert r["lift.stalled"] == 1 and r["lift.vel"] == 0
    assert chans["lift_motor"].duty == 0.0
    assert not m.is_moving()
    with pytest.raises(RequestError) as e:
        call(m, "lift", "pos", "0.5")
    assert e.value.code == "fault"
    assert e.value.detail.startswith("lift stalled: ")
    call(m, "chain", "vel", "50")  # the chain is not affected
    assert chans["chain_left"].duty == 0.5
    call(m, "ble", "stop")  # a stop is not an acknowledgement (SPEC 2.2)
    assert rows(m)["lift.stalled"] == 1
    with pytest.raises(RequestError) as e:
        call(m, "lift", "vel", "30")
    assert e.value.code == "fault" and e.value.detail.endswith("acknowledge it with ble:lift.reset")
    assert call(m, "lift", "reset") is None
    assert rows(m)["lift.stalled"] == 0
    world.stuck = False
    call(m, "lift", "pos", "0.5")
    run(m, chans, world, t, 4.0)
    assert abs(world.pos - 0.5) <= 0.03


def test_lift_settings_are_used() -> None:
    m, chans, world = build(pos=0.2, settings={"lift": {"tolerance": 0.1, "hysteresis": 0.05}})
    call(m, "lift", "pos", "0.6")
    t, _ = run(m, chans, world, 0.0, 6.0)
    assert 0.54 <= world.pos <= 0.56  # stopped at the 0.05 band
    world.pos = 0.52  # drift inside the 0.1 band: no correction
    _, duties = run(m, chans, world, t, 1.0)
    assert set(duties) == {0.0}


def test_load_tare() -> None:
    m, chans, _ = build(load_cell={"kg_per_mv_v": 50.0, "offset_mv_v": 0.1})
    chans["load_cell"].ratio = 0.3
    assert rows(m)["load.kg"] == pytest.approx(10.0)
    assert call(m, "load", "tare") is None
    assert rows(m)["load.kg"] == pytest.approx(0.0)
    chans["load_cell"].ratio = 0.5
    assert rows(m)["load.kg"] == pytest.approx(10.0)
    assert not m.is_moving()


def test_tasks_are_divisors_of_100_hz() -> None:
    m, _, _ = build()
    assert [(t.name, t.rate_hz) for t in m.tasks()] == [("lift", 50.0)]


@pytest.mark.parametrize(("override", "key"), [
    ({"lift_pot": {"volts_at_0": 2.0, "volts_at_1": 2.0}}, "lift_pot"),
    ({"load_cell": {"kg_per_mv_v": 0.0}}, "load_cell.kg_per_mv_v"),
])
def test_config_errors(override: dict[str, dict[str, Any]], key: str) -> None:
    with pytest.raises(ConfigError) as e:
        build(**override)
    assert e.value.key == key


def test_lift_hysteresis_must_be_below_tolerance() -> None:
    with pytest.raises(ConfigError) as e:
        build(settings={"lift": {"tolerance": 0.02, "hysteresis": 0.02}})
    assert e.value.key == "lift"


def test_a_robot_wide_stop_keeps_the_stall_latched() -> None:
    m, chans, world = build(pos=0.3, settings={"lift": {"stall_time": 1.0}})
    world.stuck = True
    call(m, "lift", "extend")
    run(m, chans, world, 0.0, 1.2)
    assert rows(m)["lift.stalled"] == 1
    m.stop()  # what a watchdog trip, a takeover or a re-attach does
    assert rows(m)["lift.stalled"] == 1
    with pytest.raises(RequestError):
        call(m, "lift", "extend")
    call(m, "ble", "stop")  # the operator's explicit stop too (it used to clear it)
    assert rows(m)["lift.stalled"] == 1
    call(m, "lift", "reset")  # only the acknowledgement does
    assert rows(m)["lift.stalled"] == 0


def test_no_pot_reading_stops_the_lift_and_refuses_lift_motion() -> None:
    m, chans, world = build(pos=0.95)
    call(m, "lift", "vel", "100")
    assert chans["lift_motor"].duty == 1.0
    chans["lift_pot"].read = lambda: math.nan  # a saturated or silent input
    tasks = m.tasks()
    for task in tasks:
        task.run(0.02, 0.02)
    assert chans["lift_motor"].duty == 0.0  # no end stops without a reading: stop
    for fn, args in (("vel", ("50",)), ("extend", ()), ("pos", ("0.5",))):
        with pytest.raises(RequestError) as e:
            call(m, "lift", fn, *args)
        assert e.value.code == "fault" and "no reading from lift_pot" in e.value.detail
    call(m, "lift", "vel", "0")  # stopping is always accepted
    got = call(m, "ble", "get")
    assert got is not None
    assert Response("ble", "lift", "error", ("fault", "no reading for lift.pos")) in got
    assert any(r.device == "chain" and r.prop == "vel" for r in got)  # the other rows stay


def test_tare_refuses_a_missing_reading() -> None:
    m, chans, world = build()
    chans["load_cell"].read = lambda: math.nan
    with pytest.raises(RequestError) as e:
        call(m, "load", "tare")
    assert e.value.code == "fault"
