"""Voltage (1135 conversion), SystemVoltage filter, Led blinking, VoltageDisplay sequence,
Button debouncing - all on stepped virtual time."""

from __future__ import annotations

import pytest

from ramp.hal.interfaces import AnalogInput, DigitalInput, DigitalOutput
from ramp.layers.functional import Button, Led, SystemVoltage, Voltage
from ramp.modules.voltage_display import PATTERN, VoltageDisplay


class FakeAnalog(AnalogInput):
    def __init__(self, volts: float = 0.0) -> None:
        super().__init__(None, "adc")  # type: ignore[arg-type]
        self.volts = volts

    def read(self) -> float:
        return self.volts


class RailSensor(FakeAnalog):
    """An 1135 on a rail: set `rail`, read the pin voltage the sensor would output."""

    def set_rail(self, rail: float) -> None:
        self.volts = 2.5 + 0.0681 * rail


class FakeOut(DigitalOutput):
    def __init__(self) -> None:
        super().__init__(None, "led")  # type: ignore[arg-type]
        self.writes: list[bool] = []

    def _apply(self, on: bool) -> None:
        self.writes.append(on)


class FakeIn(DigitalInput):
    def __init__(self) -> None:
        super().__init__(None, "btn")  # type: ignore[arg-type]
        self.level = False

    def read(self) -> bool:
        return self.level


# -- Voltage ------------------------------------------------------------------------------------
@pytest.mark.parametrize(("vout", "rail"), [(2.5, 0.0), (4.5, 29.368575624082235),
                                            (0.5, -29.368575624082235),
                                            (2.5 + 0.0681 * 19.0, 19.0)])
def test_voltage_1135_conversion(vout: float, rail: float) -> None:
    assert Voltage(FakeAnalog(vout)).read() == pytest.approx(rail)


def test_voltage_sensorvalue_form_agrees() -> None:
    # hardware-facts: with Vout = SensorValue/200, Voltage = SensorValue/13.62 - 36.7107
    sensor_value = 530
    v = Voltage(FakeAnalog(sensor_value / 200)).read()
    assert v == pytest.approx(sensor_value / 13.62 - 36.7107, abs=1e-3)


def test_voltage_override_and_zero_scale() -> None:
    assert Voltage.from_params(FakeAnalog(1.0), {"offset": 0.0, "scale": 0.1}).read() == \
        pytest.approx(10.0)
    with pytest.raises(ValueError):
        Voltage(FakeAnalog(), scale=0.0)


# -- SystemVoltage ------------------------------------------------------------------------------
def run_filter(sv: SystemVoltage, rail: RailSensor, profile: list[tuple[float, float]],
               rate: float = 50.0, start: float = 0.0) -> tuple[float, list[float]]:
    """Step the filter through (duration, rail volts) segments; return end time and outputs."""
    dt = 1.0 / rate
    t = start
    out = []
    for duration, volts in profile:
        rail.set_rail(volts)
        for _ in range(round(duration * rate)):
            t += dt
            sv.tick(t, dt)
            out.append(sv.value)
    return t, out


def test_filter_seeds_from_first_sample() -> None:
    rail = RailSensor()
    rail.set_rail(20.0)
    sv = SystemVoltage(Voltage(rail), tau=2.0)
    assert sv.value == pytest.approx(20.0)  # before any tick: instantaneous
    sv.tick(0.0, 0.0)
    assert sv.value == pytest.approx(20.0)


def test_filter_hides_a_short_load_spike() -> None:
    rail = RailSensor()
    sv = SystemVoltage(Voltage(rail), tau=2.0)
    _, out = run_filter(sv, rail, [(2.0, 20.0), (0.2, 16.0), (3.0, 20.0)])
    # a 4 V, 200 ms dip moves the output by about 4 * (1 - e^-0.1) = 0.38 V
    assert min(out) > 19.5
    assert min(out) < 19.9  # it does see it
    assert out[-1] == pytest.approx(20.0, abs=0.1)


def test_filter_follows_a_sustained_drop() -> None:
    rail = RailSensor()
    sv = SystemVoltage(Voltage(rail), tau=2.0)
    _, out = run_filter(sv, rail, [(1.0, 20.0), (10.0, 18.0)])
    # after one time constant about 63 % of the step
    one_tau = out[50 + 100 - 1]
    assert one_tau == pytest.approx(20.0 - 2.0 * 0.632, abs=0.05)
    assert out[-1] == pytest.approx(18.0, abs=0.02)


def test_filter_same_response_at_other_rates() -> None:
    ends = []
    for rate in (10.0, 50.0, 100.0):
        rail = RailSensor()
        sv = SystemVoltage(Voltage(rail), tau=1.0)
        _, out = run_filter(sv, rail, [(0.1 if rate == 10 else 0.02, 20.0), (1.0, 17.0)],
                            rate=rate)
        ends.append(out[-1])
    assert max(ends) - min(ends) < 0.01


# -- Led ----------------------------------------------------------------------------------------
def test_led_on_off_written_at_once() -> None:
    ch = FakeOut()
    led = Led(ch)
    led.set(True)
    assert ch.state and led.is_on
    led.set(False)
    assert not ch.state and not led.is_on
    assert ch.writes == [True, False]


def test_led_blinks_at_its_rate_from_ticks() -> None:
    ch = FakeOut()
    led = Led(ch)
    led.blink(2.0)  # 0.25 s on, 0.25 s off
    states = []
    for i in range(40):  # 2 s at 20 Hz
        led.tick(10.0 + i * 0.05)
        states.append(ch.state)
    assert states[:10] == [True] * 5 + [False] * 5
    assert states == (states[:10]) * 4
    assert ch.writes.count(True) == 4 and ch.writes.count(False) == 4
    assert not led.is_on  # a blinking LED is not "on"
    led.blink(2.0)  # same rate again: phase kept
    led.tick(12.0)
    assert ch.state is True
    led.set(False)
    led.tick(12.1)
    assert ch.state is False


def test_led_rejects_bad_rate() -> None:
    with pytest.raises(ValueError):
        Led(FakeOut()).blink(0.0)


# -- VoltageDisplay -----------------------------------------------------------------------------
def make_display(**kw: float) -> tuple[VoltageDisplay, tuple[FakeOut, FakeOut, FakeOut]]:
    outs = (FakeOut(), FakeOut(), FakeOut())
    disp = VoltageDisplay(Led(outs[0]), Led(outs[1]), Led(outs[2]),
                          (17.6, 18.2, 18.8, 19.4, 20.0), **kw)
    return disp, outs


def test_display_sequence_over_a_falling_voltage() -> None:
    disp, outs = make_display(blink_hz=2.0, hysteresis=0.1)
    seen: list[tuple[str, str, str]] = []
    t = 0.0
    volts = 21.0
    while volts > 16.5:
        disp.tick(t, volts)
        modes = tuple(led.mode for led in disp.leds)
        if not seen or seen[-1] != modes:
            seen.append(modes)  # type: ignore[arg-type]
        t += 0.05
        volts -= 0.005
    assert seen == [
        ("on", "on", "on"),
        ("blink", "on", "on"),
        ("off", "on", "on"),
        ("off", "blink", "on"),
        ("off", "off", "on"),
        ("off", "off", "blink"),
    ]
    assert seen == list(reversed(PATTERN))


@pytest.mark.parametrize(("volts", "level"), [(20.5, 5), (20.0, 5), (19.99, 4), (19.4, 4),
                                              (19.0, 3), (18.5, 2), (18.0, 1), (17.6, 1),
                                              (17.59, 0), (3.0, 0)])
def test_display_levels(volts: float, level: int) -> None:
    disp, outs = make_display()
    disp.tick(0.0, volts)
    assert disp.level == level
    high, mid, low = PATTERN[level]
    # at t=0 a blinking LED is in its lit half
    assert [o.state for o in outs] == [m != "off" for m in (high, mid, low)]


def test_display_blinking_led_really_toggles() -> None:
    disp, outs = make_display(blink_hz=1.0)
    states = []
    for i in range(40):
        disp.tick(i * 0.05, 19.7)  # level 4: high blinks
        states.append((outs[0].state, outs[1].state, outs[2].state))
    assert {s[0] for s in states} == {True, False}
    assert all(s[1] and s[2] for s in states)
    assert sum(1 for s in states if s[0]) == 20  # 50 % duty


def test_display_hysteresis_no_flicker_at_a_threshold() -> None:
    disp, _ = make_display(hysteresis=0.1)
    disp.tick(0.0, 19.3)
    assert disp.level == 3
    levels = set()
    for i in range(200):  # noise of +-0.05 V around the 19.4 V threshold
        v = 19.4 + (0.05 if i % 2 else -0.05)
        disp.tick(0.05 * i, v)
        levels.add(disp.level)
    assert levels == {3}  # a dip below drops to 3 at once; 19.45 never climbs back
    disp.tick(20.0, 19.51)
    assert disp.level == 4  # beyond threshold + band: climbs


def test_display_rejects_unordered_thresholds() -> None:
    with pytest.raises(ValueError):
        VoltageDisplay(Led(FakeOut()), Led(FakeOut()), Led(FakeOut()),
                       (17.6, 18.8, 18.2, 19.4, 20.0))


# -- Button -------------------------------------------------------------------------------------
def test_button_debounces_bounces() -> None:
    ch = FakeIn()
    b = Button(ch, debounce=0.02)
    t = 0.0
    b.tick(t)
    assert not b.pressed
    # contact bounce: 10 ms on, 10 ms off, ... never holds 20 ms
    for level in (True, False, True, False, True, False):
        ch.level = level
        t += 0.01
        b.tick(t)
        assert not b.pressed
    ch.level = True
    t += 0.01
    b.tick(t)
    t += 0.01
    b.tick(t)
    assert not b.pressed  # held 10 ms
    t += 0.01
    b.tick(t)
    assert b.pressed  # held 20 ms
    ch.level = False
    t += 0.01
    b.tick(t)
    assert b.pressed
    t += 0.02
    b.tick(t)
    assert not b.pressed


def test_button_active_low_and_first_sample() -> None:
    ch = FakeIn()
    ch.level = False  # line low = pressed
    b = Button.from_params(ch, {"debounce": 0.05, "active_low": True})
    b.tick(0.0)
    assert b.pressed  # the first reading is taken as is
    ch.level = True
    b.tick(0.01)
    b.tick(0.05)
    assert b.pressed
    b.tick(0.06)
    assert not b.pressed
