"""BaseModule: the SPEC 2.1 table, get rows, parameter checks through Module.lookup, stop,
is_moving, and its tasks (buttons, battery filter, LED display) on stepped time."""

from __future__ import annotations

from typing import Any

import pytest

from ramp.errors import ConfigError, RequestError
from ramp.hal.interfaces import AnalogInput, DigitalInput, DigitalOutput, MotorChannel
from ramp.layers.module_distribution import BoundDevice, Function
from ramp.mcp.messages import Request, Response
from ramp.modules.base import BaseModule


class FakeMotor(MotorChannel):
    def __init__(self, label: str) -> None:
        super().__init__(None, label)  # type: ignore[arg-type]

    def _apply(self, duty: float) -> None:
        pass


class FakeAnalog(AnalogInput):
    def __init__(self, label: str) -> None:
        super().__init__(None, label)  # type: ignore[arg-type]
        self.volts = 2.5 + 0.0681 * 20.5

    def read(self) -> float:
        return self.volts


class FakeIn(DigitalInput):
    def __init__(self, label: str) -> None:
        super().__init__(None, label)  # type: ignore[arg-type]
        self.level = False

    def read(self) -> bool:
        return self.level


class FakeOut(DigitalOutput):
    def __init__(self, label: str) -> None:
        super().__init__(None, label)  # type: ignore[arg-type]

    def _apply(self, on: bool) -> None:
        pass


WHEELS = ("lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel")
MOTOR_DEFAULTS = {"polarity": 1, "full_duty": 1.0, "deadband": 0.0}


def build(settings: dict[str, dict[str, Any]] | None = None,
          **overrides: dict[str, Any]) -> tuple[BaseModule, dict[str, Any]]:
    chans: dict[str, Any] = {w: FakeMotor(w) for w in WHEELS}
    chans["battery"] = FakeAnalog("battery")
    chans["l_button"] = FakeIn("l_button")
    chans["r_button"] = FakeIn("r_button")
    for n in ("user_led", "led_high", "led_mid", "led_low"):
        chans[n] = FakeOut(n)
    params: dict[str, dict[str, Any]] = {w: dict(MOTOR_DEFAULTS) for w in WHEELS}
    params["battery"] = {"offset": 2.5, "scale": 0.0681}
    for b in ("l_button", "r_button"):
        params[b] = {"debounce": 0.02, "active_low": False}
    for name, extra in overrides.items():
        params.setdefault(name, {}).update(extra)
    devices = {n: BoundDevice(ch, params.get(n, {})) for n, ch in chans.items()}
    return BaseModule("base", devices, settings or {}), chans


def call(m: BaseModule, device: str, function: str, *params: str) -> list[Response] | None:
    fn, values = m.lookup(Request("base", device, function, params))
    return fn.run(*values)


def test_device_and_settings_schema() -> None:
    assert set(BaseModule.devices) == {*WHEELS, "battery", "l_button", "r_button", "user_led",
                                       "led_high", "led_mid", "led_low"}
    kinds = {n: s.kind for n, s in BaseModule.devices.items()}
    assert all(kinds[w] == "motor" for w in WHEELS)
    assert kinds["battery"] == "analog_in"
    assert kinds["l_button"] == kinds["r_button"] == "digital_in"
    assert kinds["user_led"] == kinds["led_low"] == "digital_out"
    pol = BaseModule.devices["lf_wheel"].fields["polarity"]
    assert pol.default == 1 and pol.choices == (-1, 1)
    assert BaseModule.devices["lf_wheel"].fields["full_duty"].default == 1.0
    assert BaseModule.devices["lf_wheel"].fields["deadband"].hi == 0.5
    assert BaseModule.devices["l_button"].fields["debounce"].default == 0.02
    assert BaseModule.devices["l_button"].fields["active_low"].default is False
    assert set(BaseModule.settings) == {"battery_filter", "voltage_display"}


def test_function_table_is_spec_2_1() -> None:
    m, _ = build()
    table = {k: (f.kind, [p.describe() for p in f.params]) for k, f in m.functions.items()}
    assert table == {
        ("base", "get"): ("read", []),
        ("base", "stop"): ("stop", []),
        ("base", "describe"): ("read", []),
        ("base", "drive"): ("motion", ["int -100..100", "float"]),
        **{(w, "vel"): ("motion", ["int -100..100"]) for w in WHEELS},
        ("user_led", "on"): ("state", ["int 0..1"]),
    }


def test_get_rows_in_table_5_4_order() -> None:
    m, _ = build()
    rows = call(m, "base", "get")
    assert rows is not None
    # Table 5.4's rows in its order, then the battery's charge (% from its YAML model, the
    # fleet's batteryState) after them.
    assert [(r.device, r.prop) for r in rows] == [
        ("lf_wheel", "vel"), ("lb_wheel", "vel"), ("rf_wheel", "vel"), ("rb_wheel", "vel"),
        ("l_button", "press"), ("r_button", "press"), ("battery", "volt"), ("user_led", "on"),
        ("battery", "charge")]
    assert all(r.module == "base" for r in rows)
    vals = [r.values[0] for r in rows]
    assert vals[:6] == [0, 0, 0, 0, 0, 0] and all(type(v) is int for v in vals[:6])
    assert type(vals[6]) is float and vals[6] == pytest.approx(20.5)
    assert vals[7] == 0


def test_describe_rows() -> None:
    m, _ = build()
    desc = call(m, "base", "describe")
    assert desc is not None
    assert Response("base", "base", "function", ("drive", "int -100..100", "float")) in desc
    assert Response("base", "lf_wheel", "function", ("vel", "int -100..100")) in desc
    assert Response("base", "user_led", "function", ("on", "int 0..1")) in desc
    assert Response("base", "battery", "property", ("volt", "float", "V")) in desc
    assert Response("base", "l_button", "property", ("press", "int")) in desc


@pytest.mark.parametrize(("device", "function", "params"), [
    ("lf_wheel", "vel", ("101",)),
    ("rb_wheel", "vel", ("-101",)),
    ("lb_wheel", "vel", ("1.5",)),
    ("rf_wheel", "vel", ()),
    ("lf_wheel", "vel", ("1", "2")),
    ("base", "drive", ("50",)),
    ("base", "drive", ("50", "nan")),
    ("base", "drive", ("50", "inf")),
    ("base", "drive", ("50.5", "0")),
    ("base", "drive", ("200", "0")),
    ("user_led", "on", ("2",)),
    ("user_led", "on", ("true",)),
    ("base", "stop", ("1",)),
    ("base", "get", ("x",)),
])
def test_bad_params(device: str, function: str, params: tuple[str, ...]) -> None:
    m, chans = build()
    with pytest.raises(RequestError) as e:
        m.lookup(Request("base", device, function, params))
    assert e.value.code == "bad_params"
    assert e.value.detail.startswith(function)
    assert all(chans[w].duty == 0.0 for w in WHEELS)


def test_bad_params_detail_wording() -> None:
    m, _ = build()
    with pytest.raises(RequestError) as e:
        m.lookup(Request("base", "lf_wheel", "vel", ("101",)))
    assert e.value.detail == "vel takes one int in -100..100"


def test_unknown_device_and_function() -> None:
    m, _ = build()
    with pytest.raises(RequestError) as e:
        m.lookup(Request("base", "lift", "vel", ("1",)))
    assert e.value.code == "unknown_device"
    with pytest.raises(RequestError) as e:
        m.lookup(Request("base", "lf_wheel", "pos", ("1",)))
    assert e.value.code == "unknown_function"


def test_drive_through_lookup_sets_duties_and_get() -> None:
    m, chans = build(rf_wheel={"polarity": -1}, rb_wheel={"polarity": -1})
    assert call(m, "base", "drive", "60", "45") is None  # an action: no response
    assert [chans[w].duty for w in WHEELS] == [0.6, 0.6, 0.0, 0.0]
    assert call(m, "base", "drive", "-80", "-270.0") is None  # -270 = 90: spin clockwise
    assert [chans[w].duty for w in WHEELS] == [-0.8, -0.8, -0.8, -0.8]  # right side reversed
    rows = call(m, "base", "get")
    assert rows is not None
    assert [r.values[0] for r in rows[:4]] == [-80, -80, 80, 80]
    assert m.is_moving()


def test_wheel_vel_and_full_duty_and_stop_zeroes_every_motor() -> None:
    m, chans = build(lb_wheel={"full_duty": 0.5})
    for i, w in enumerate(WHEELS):
        call(m, w, "vel", str(20 * (i + 1)))
    assert [chans[w].duty for w in WHEELS] == pytest.approx([0.2, 0.2, 0.6, 0.8])
    assert m.is_moving()
    assert call(m, "base", "stop") is None
    assert [chans[w].duty for w in WHEELS] == [0.0] * 4
    rows = call(m, "base", "get")
    assert rows is not None and [r.values[0] for r in rows[:4]] == [0, 0, 0, 0]
    assert not m.is_moving()
    call(m, "lf_wheel", "vel", "0")
    assert not m.is_moving()


def test_start_begins_from_rest() -> None:
    m, chans = build()
    call(m, "base", "drive", "100", "0")
    m.start(0.0)
    assert [chans[w].duty for w in WHEELS] == [0.0] * 4


def test_user_led_is_state_and_reported() -> None:
    m, chans = build()
    assert call(m, "user_led", "on", "1") is None
    assert chans["user_led"].state is True
    assert not m.is_moving()
    rows = call(m, "base", "get")
    assert rows is not None and rows[7].values == (1,)
    call(m, "user_led", "on", "0")
    assert chans["user_led"].state is False


def run_tasks(m: BaseModule, t0: float, seconds: float) -> float:
    """A tiny stand-in for the scheduler: a 100 Hz base tick, each task at its divisor."""
    tasks = m.tasks()
    last = {task.name: t0 for task in tasks}
    steps = round(seconds * 100)
    t = t0
    for i in range(1, steps + 1):
        t = t0 + i / 100
        for task in tasks:
            div = round(100 / task.rate_hz)
            if i % div == 0:
                task.run(t, t - last[task.name])
                last[task.name] = t
    return t


def test_tasks_are_divisors_of_100_hz() -> None:
    m, _ = build()
    rates = {task.name: task.rate_hz for task in m.tasks()}
    assert set(rates) == {"buttons", "battery", "leds"}  # the supervisor prefixes "base."
    assert all((100 / r).is_integer() for r in rates.values())


def test_buttons_are_debounced_in_the_get() -> None:
    m, chans = build(r_button={"active_low": True})
    chans["r_button"].level = True  # active low: released
    t = run_tasks(m, 0.0, 0.1)
    rows = call(m, "base", "get")
    assert rows is not None and (rows[4].values, rows[5].values) == ((0,), (0,))
    chans["l_button"].level = True
    chans["r_button"].level = False
    t = run_tasks(m, t, 0.01)
    rows = call(m, "base", "get")
    assert rows is not None and (rows[4].values, rows[5].values) == ((0,), (0,))
    run_tasks(m, t, 0.03)
    rows = call(m, "base", "get")
    assert rows is not None and (rows[4].values, rows[5].values) == ((1,), (1,))


def test_battery_filter_and_led_display_over_a_falling_rail() -> None:
    m, chans = build()  # default filter time constant: 2 s
    leds = [chans[n] for n in ("led_high", "led_mid", "led_low")]
    t = run_tasks(m, 0.0, 0.5)
    assert [o.state for o in leds] == [True, True, True]
    # a 0.1 s load spike down to 17 V: filtered, the display does not react
    chans["battery"].volts = 2.5 + 0.0681 * 17.0
    t = run_tasks(m, t, 0.1)
    chans["battery"].volts = 2.5 + 0.0681 * 20.5
    rows = call(m, "base", "get")
    assert rows is not None and rows[6].values[0] > 19.5
    assert m.display.level == 5
    # a sustained fall, 20.5 V -> 16.5 V over 40 s: every level in order
    levels = []
    for i in range(400):
        chans["battery"].volts = 2.5 + 0.0681 * (20.5 - 0.01 * i)
        t = run_tasks(m, t, 0.1)
        if not levels or levels[-1] != m.display.level:
            levels.append(m.display.level)
    assert levels == [5, 4, 3, 2, 1, 0]
    t = run_tasks(m, t, 10.0)  # let the filter settle at the final 16.5 V
    rows = call(m, "base", "get")
    assert rows is not None and rows[6].values[0] == pytest.approx(16.5, abs=0.1)
    # at level 0 the low LED blinks, the others are dark
    seen = set()
    for _ in range(20):
        t = run_tasks(m, t, 0.05)
        seen.add(tuple(o.state for o in leds))
    assert seen == {(False, False, True), (False, False, False)}


def test_voltage_display_thresholds_from_settings() -> None:
    m, _ = build(settings={"voltage_display": {"high_blink": 24.0, "high_off": 23.0,
                                                "mid_blink": 22.0, "mid_off": 21.0,
                                                "low_blink": 20.0, "blink_hz": 1.0,
                                                "hysteresis": 0.0}})
    run_tasks(m, 0.0, 0.1)
    assert m.display.level == 1  # 20.5 V on a 24 V-threshold display


def test_bad_settings_are_config_errors() -> None:
    with pytest.raises(ConfigError) as e:
        build(settings={"voltage_display": {"high_blink": 18.0, "high_off": 19.0,
                                             "mid_blink": 18.8, "mid_off": 18.2,
                                             "low_blink": 17.6, "blink_hz": 2.0,
                                             "hysteresis": 0.1}})
    assert "voltage_display" in str(e.value)


def test_missing_or_wrong_device_is_a_config_error() -> None:
    m, chans = build()
    devices = {n: BoundDevice(ch, {}) for n, ch in chans.items()}
    del devices["led_mid"]
    with pytest.raises(ConfigError) as e:
        BaseModule("base", devices, {})
    assert e.value.key == "led_mid"
    devices["led_mid"] = BoundDevice(FakeMotor("x"), {})
    with pytest.raises(ConfigError):
        BaseModule("base", devices, {})


def test_module_name_is_its_own_device() -> None:
    _, chans = build()
    devices = {n: BoundDevice(ch, {}) for n, ch in chans.items()}
    m = BaseModule("base2", devices, {})
    assert isinstance(m.functions[("base2", "drive")], Function)
    assert ("base", "drive") not in m.functions


def test_battery_filter_time_constant_from_settings() -> None:
    fast, chans_f = build(settings={"battery_filter": {"time_constant": 0.1}})
    slow, chans_s = build()
    run_tasks(fast, 0.0, 0.2)
    run_tasks(slow, 0.0, 0.2)
    for chans in (chans_f, chans_s):
        chans["battery"].volts = 2.5 + 0.0681 * 18.5
    run_tasks(fast, 0.2, 0.5)
    run_tasks(slow, 0.2, 0.5)
    assert fast.voltage.value == pytest.approx(18.5, abs=0.05)
    assert slow.voltage.value > 19.5
