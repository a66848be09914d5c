"""The `phidget` driver against fakes of the Phidget22 channel classes (tests/fake_phidget22.py).

The fakes keep Phidget22's method names and call the registered handlers the way
libphidget22 does: from threads that are not the scheduler's. Phidget22 itself is not
needed (tests/unit/test_phidget_no_board.py runs against the real one); the missing-library
paths are exercised as the real package fails.
"""

from __future__ import annotations

import logging
import math
import sys
import threading
from typing import Any

import pytest

from ramp.errors import ConfigError, DeviceError
from ramp.hal import driver_class
from ramp.hal.phidget import PhidgetApi, PhidgetBus
from tests.fake_phidget22 import (
    EEPHIDGET_SATURATION,
    EPHIDGET_NOTATTACHED,
    FakeAsyncDigitalOutput,
    FakeBoard,
    FakeBridgeGain,
    FakeDigitalInput,
    FakeDigitalOutput,
    FakePhidgetException,
    FakeVoltageInput,
    FakeVoltageRatioInput,
    on_library_thread,
)


class Kit:
    """A bus with one channel of each kind, as MARTE wires its boards."""

    def __init__(self, board: FakeBoard | None = None, **params: Any) -> None:
        self.board = board or FakeBoard()
        self.bus = PhidgetBus("ble_io", params, api=self.board.api)
        self.battery = self.bus.channel("analog_in", "base.battery", {"channel": 3})
        self.load = self.bus.channel("bridge_in", "ble.load", {"channel": 0, "gain": 64})
        self.button = self.bus.channel("digital_in", "base.l_button", {"channel": 1})
        self.led = self.bus.channel("digital_out", "base.user_led", {"channel": 2})

    def handles(self) -> tuple[Any, Any, Any, Any]:
        b = self.board
        return (b.of(FakeVoltageInput, 3), b.of(FakeVoltageRatioInput, 0),
                b.of(FakeDigitalInput, 1), b.of(FakeDigitalOutput, 2))

    def plug_all(self, button: bool = False) -> None:
        ai, br, di, do = self.handles()
        di.state = button

        def lib() -> None:
            for h in (ai, br, di, do):
                h.plug()
            ai.fire("sample", 2.5)
            br.fire("sample", 0.0012)

        on_library_thread(lib)


# -- build and registry ------------------------------------------------------------------------
def test_registered_as_phidget() -> None:
    assert driver_class("phidget") is PhidgetBus
    assert PhidgetBus.driver_name == "phidget"


def test_fields_defaults_and_ranges() -> None:
    bus = PhidgetBus("io", {})
    assert (bus.serial, bus.hub_port, bus.label) == (-1, -1, "")
    assert (bus.data_interval, bus.attach_timeout) == (0.02, 2.0)
    assert PhidgetBus.channel_fields["bridge_in"]["gain"].choices == (1, 8, 16, 32, 64, 128)
    assert PhidgetBus.channel_fields["bridge_in"]["gain"].default == 128
    assert PhidgetBus.channel_fields["bridge_in"]["channel"].hi == 3
    for kind in ("analog_in", "digital_in", "digital_out"):
        f = PhidgetBus.channel_fields[kind]["channel"]
        assert (f.lo, f.hi) == (0, 7)
    with pytest.raises(ConfigError, match=r"buses\.io\.serial"):
        PhidgetBus("io", {"serial": "kit"})
    with pytest.raises(ConfigError, match="data_interval"):
        PhidgetBus("io", {"data_interval": 0.0})


@pytest.mark.parametrize(("key", "value", "says"), [
    ("serial", 2**32 + 300001, r"buses\.io\.serial: 4295267297 is not a Phidget serial "
     r"number or -1 for any \(-1-2147483647\)"),
    ("serial", 10**30, r"buses\.io\.serial: 1000000000000000000000000000000 is not"),
    ("hub_port", 6, r"buses\.io\.hub_port: 6 is not a VINT hub port or -1 for any \(-1-5\)"),
])
def test_serial_and_hub_port_are_bounded_as_phidget22_takes_them(key: str, value: int,
                                                                 says: str) -> None:
    """A serial past 32 bits was cut by ctypes and matched another board, and `hub_port: 99`
    waited for a port no hub has; autonomy.yaml already stopped at port 5."""
    with pytest.raises(ConfigError, match=says):
        PhidgetBus("io", {key: value})


def test_bad_channel_specs_are_rejected() -> None:
    bus = PhidgetBus("io", {}, api=FakeBoard().api)
    with pytest.raises(ValueError, match="8 is not an analog input"):
        bus.channel("analog_in", "a.b", {"channel": 8})
    with pytest.raises(ValueError, match="gain"):
        bus.channel("bridge_in", "a.b", {"channel": 0, "gain": 2})
    with pytest.raises(ValueError, match="no motor channels"):
        bus.channel("motor", "a.b", {"channel": 0})


def test_one_output_one_driver_but_inputs_are_shared() -> None:
    board = FakeBoard()
    bus = PhidgetBus("io", {}, api=board.api)
    a = bus.channel("analog_in", "base.battery", {"channel": 0})
    b = bus.channel("analog_in", "ble.battery", {"channel": 0})
    bus.channel("digital_out", "base.user_led", {"channel": 0})
    with pytest.raises(ValueError, match="already driven by base.user_led"):
        bus.channel("digital_out", "ble.led", {"channel": 0})
    bus.open(0.0)
    assert len([c for c in board.created if isinstance(c, FakeVoltageInput)]) == 1
    ai = board.of(FakeVoltageInput, 0)
    on_library_thread(lambda: (ai.plug(), ai.fire("sample", 4.25)))
    bus.tick(0.01, 0.01)
    assert a.read() == b.read() == 4.25


def test_building_a_bus_does_not_need_phidget22(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in [m for m in sys.modules if m.split(".")[0] == "Phidget22"] + ["Phidget22"]:
        monkeypatch.setitem(sys.modules, name, None)  # any import of it now fails
    bus = PhidgetBus("ble_io", {"serial": 5})
    bus.channel("analog_in", "base.battery", {"channel": 0})
    with pytest.raises(DeviceError) as info:
        bus.open(0.0)
    msg = str(info.value)
    assert msg.startswith("bus ble_io: ")
    assert "Phidget22 package is not installed" in msg
    assert "pip install 'ramp[phidget]'" in msg and "apt-get install libusb-1.0-0" in msg
    assert isinstance(info.value.__cause__, ImportError)
    assert not bus.is_open and not bus.ready()


@pytest.mark.parametrize("text", [
    "libusb-1.0.so.0: cannot open shared object file: No such file or directory",
    "libphidget22.so.0: cannot open shared object file: No such file or directory",
])
def test_missing_native_library_is_a_clear_device_error(text: str) -> None:
    tries = []

    def ctor() -> Any:
        tries.append(1)
        raise OSError(text)

    api = PhidgetApi(VoltageInput=ctor, VoltageRatioInput=ctor, DigitalInput=ctor,
                     DigitalOutput=ctor, PhidgetException=FakePhidgetException,
                     BridgeGain=FakeBridgeGain)
    bus = PhidgetBus("base_io", {}, api=api)
    bus.channel("digital_in", "base.l_button", {"channel": 0})
    with pytest.raises(DeviceError) as info:
        bus.open(0.0)
    msg = str(info.value)
    assert text in msg
    assert "pip install 'ramp[phidget]'" in msg and "apt-get install libusb-1.0-0" in msg
    assert isinstance(info.value.__cause__, OSError)
    assert not bus.is_open
    # The retry a second later fails the same way without poking the library again.
    with pytest.raises(DeviceError, match="apt-get install libusb-1.0-0") as again:
        bus.open(1.0)
    assert isinstance(again.value.__cause__, OSError)
    assert len(tries) == 1


# -- open --------------------------------------------------------------------------------------
def test_open_sets_matching_registers_handlers_and_does_not_wait() -> None:
    kit = Kit(serial=123456, hub_port=2, label="marte")
    kit.bus.open(0.0)
    handles = kit.handles()
    assert len(kit.board.created) == 4
    for h, ch in zip(handles, (3, 0, 1, 2), strict=True):
        assert (h.serial, h.hub_port, h.channel, h.label) == (123456, 2, ch, "marte")
        assert h.is_open and h.calls.count("open") == 1
        opened = h.calls.index("open")
        for name in ("setDeviceSerialNumber", "setHubPort", "setChannel", "setOnAttachHandler",
                     "setOnDetachHandler", "setOnErrorHandler"):
            assert h.calls.index(name) < opened, name
    assert handles[0].calls.index("setOnVoltageChangeHandler") < handles[0].calls.index("open")
    assert "setOnVoltageRatioChangeHandler" in handles[1].calls
    assert "setOnStateChangeHandler" in handles[2].calls
    assert kit.bus.is_open and not kit.bus.ready()
    kit.bus.tick(0.01, 0.01)  # nothing attached yet, and that is fine for now
    assert not kit.bus.ready()


def test_default_matching_is_any_device_and_no_label() -> None:
    kit = Kit()
    kit.bus.open(0.0)
    ai = kit.handles()[0]
    assert (ai.serial, ai.hub_port) == (-1, -1)
    assert "setDeviceLabel" not in ai.calls


def test_failed_open_closes_what_it_opened() -> None:
    kit = Kit()
    kit.board.fail_open.add(FakeDigitalInput)
    with pytest.raises(DeviceError, match="cannot open the Phidget channels: code 13"):
        kit.bus.open(0.0)
    assert not kit.bus.is_open
    assert kit.board.open_handles() == []
    assert kit.board.of(FakeVoltageInput, 3).close_count == 1


# -- events ------------------------------------------------------------------------------------
def test_handlers_only_queue_and_tick_applies_them() -> None:
    kit = Kit()
    kit.bus.open(0.0)
    kit.plug_all(button=True)
    # The library thread has delivered attach and samples, but nothing changed yet.
    assert not kit.bus.ready()
    assert math.isnan(kit.battery.read()) and math.isnan(kit.load.read())
    assert all(threading.get_ident() not in h.handler_threads for h in kit.handles())
    kit.bus.tick(0.01, 0.01)
    assert kit.bus.ready()
    assert kit.battery.read() == 2.5
    assert kit.load.read() == pytest.approx(1.2)  # 0.0012 V/V is 1.2 mV/V
    assert kit.button.read() is True  # seeded from getState: no change event came


def test_attach_configures_each_channel() -> None:
    kit = Kit(data_interval=0.05)
    kit.bus.open(0.0)
    kit.plug_all()
    kit.bus.tick(0.01, 0.01)
    ai, br, _di, _do = kit.handles()
    assert (ai.data_interval, ai.trigger, ai.sensor_type) == (50, 0.0, 0)
    assert (br.data_interval, br.trigger) == (50, 0.0)
    assert br.bridge_enabled is True
    assert br.gain == FakeBridgeGain.BRIDGE_GAIN_64


def test_data_interval_is_clamped_to_the_channel() -> None:
    kit = Kit(data_interval=0.001)
    kit.bus.open(0.0)
    kit.plug_all()
    kit.bus.tick(0.01, 0.01)
    ai, br, _di, _do = kit.handles()
    assert ai.data_interval == 1
    assert br.data_interval == 8  # the bridge's minimum


def test_samples_keep_flowing_while_the_tick_runs() -> None:
    kit = Kit()
    kit.bus.open(0.0)
    kit.plug_all()
    kit.bus.tick(0.01, 0.01)
    ai, br, di, _do = kit.handles()
    n = 3000
    done = threading.Event()

    def lib() -> None:
        for i in range(n):
            ai.fire("sample", i / 1000.0)
            br.fire("sample", -i / 1e6)
            di.fire("sample", i % 2 == 1)
        done.set()

    t = threading.Thread(target=lib)
    t.start()
    now = 0.01
    seen = []
    while not done.is_set():
        now += 0.01
        kit.bus.tick(now, 0.01)
        seen.append(kit.battery.read())
    t.join(5.0)
    kit.bus.tick(now + 0.01, 0.01)
    assert kit.battery.read() == (n - 1) / 1000.0
    assert kit.load.read() == pytest.approx(-(n - 1) / 1000.0)
    assert kit.button.read() is True
    assert seen == sorted(seen)  # newest sample wins, never an older one after it


def test_a_digital_input_without_a_value_waits() -> None:
    board = FakeBoard()
    bus = PhidgetBus("io", {}, api=board.api)
    button = bus.channel("digital_in", "base.r_button", {"channel": 4})
    bus.open(0.0)
    di = board.of(FakeDigitalInput, 4)
    on_library_thread(di.plug)  # attached, but the library has no state yet
    bus.tick(0.01, 0.01)
    assert not bus.ready()
    di.state = False
    bus.tick(0.02, 0.01)
    assert bus.ready() and button.read() is False
    on_library_thread(lambda: di.fire("sample", 1))
    bus.tick(0.03, 0.01)
    assert button.read() is True


def test_error_events_are_logged_once_and_count_as_alive(
    caplog: pytest.LogCaptureFixture,
) -> None:
    kit = Kit()
    kit.bus.open(0.0)
    ai, br, di, do = kit.handles()
    di.state = False

    def lib() -> None:
        for h in (ai, br, di, do):
            h.plug()
        br.fire("sample", 0.0)
        for _ in range(5):  # a saturated input sends errors instead of samples
            ai.fire("error", EEPHIDGET_SATURATION, "Saturation Detected.")

    on_library_thread(lib)
    with caplog.at_level(logging.WARNING, logger="ramp.hal.phidget"):
        kit.bus.tick(0.01, 0.01)
    assert kit.bus.ready()  # the board answers: the module can attach
    assert math.isnan(kit.battery.read())
    assert kit.bus.error_counts == {EEPHIDGET_SATURATION: 5}
    warnings = [r for r in caplog.records if "Saturation" in r.getMessage()]
    assert len(warnings) == 1 and "base.battery" in warnings[0].getMessage()
    on_library_thread(lambda: ai.fire("sample", 4.9))
    kit.bus.tick(0.02, 0.01)
    assert kit.battery.read() == 4.9


# -- faults ------------------------------------------------------------------------------------
def test_detach_raises_from_tick_naming_bus_and_channel() -> None:
    kit = Kit()
    kit.bus.open(0.0)
    kit.plug_all()
    kit.bus.tick(0.01, 0.01)
    ai = kit.handles()[0]
    on_library_thread(ai.unplug)
    with pytest.raises(DeviceError) as info:
        kit.bus.tick(0.02, 0.01)
    err = info.value
    assert err.bus == "ble_io" and err.device == "base.battery"
    assert str(err) == "bus ble_io device base.battery: Phidget analog_in channel 3 detached"
    assert not kit.bus.ready()


def test_attach_timeout_names_the_missing_channels() -> None:
    kit = Kit(serial=4242, attach_timeout=2.0)
    kit.bus.open(10.0)
    _ai, br, di, do = kit.handles()
    di.state = True
    on_library_thread(lambda: (br.plug(), di.plug(), do.plug(), br.fire("sample", 0.0)))
    kit.bus.tick(11.9, 0.01)
    kit.bus.tick(12.0, 0.01)
    with pytest.raises(DeviceError) as info:
        kit.bus.tick(12.01, 0.01)
    err = info.value
    assert err.bus == "ble_io" and err.device == "base.battery"
    assert "serial 4242 not attached within 2 s: analog_in 3 " in str(err)
    assert "bridge_in" not in str(err)


def test_attached_but_silent_input_times_out() -> None:
    kit = Kit(attach_timeout=0.5)
    kit.bus.open(0.0)
    ai, br, di, do = kit.handles()
    di.state = True
    on_library_thread(lambda: (ai.plug(), br.plug(), di.plug(), do.plug(),
                               ai.fire("sample", 1.0)))
    kit.bus.tick(0.4, 0.01)
    with pytest.raises(DeviceError, match="attached but sent no data within 0.5 s: bridge_in 0"):
        kit.bus.tick(0.6, 0.01)


def test_close_closes_every_channel_once_and_swallows_errors() -> None:
    kit = Kit()
    kit.bus.open(0.0)
    kit.plug_all()
    kit.bus.tick(0.01, 0.01)
    handles = kit.handles()
    handles[1].close_raises = True
    kit.bus.close()
    assert [h.close_count for h in handles] == [1, 1, 1, 1]
    assert kit.board.open_handles() == []
    assert not kit.bus.ready() and not kit.bus.is_open
    kit.bus.close()
    kit.bus._close()  # even the raw hook is safe twice
    assert [h.close_count for h in handles] == [1, 1, 1, 1]


def test_reopen_after_a_detach_reattaches_with_fresh_channels() -> None:
    kit = Kit()
    kit.bus.open(0.0)
    kit.plug_all()
    kit.bus.tick(0.01, 0.01)
    old = kit.handles()
    on_library_thread(old[2].unplug)
    with pytest.raises(DeviceError):
        kit.bus.tick(0.02, 0.01)
    kit.bus.close()  # what the supervisor does, then it retries about a second later
    kit.bus.open(1.0)
    new = kit.handles()
    assert all(n is not o for n, o in zip(new, old, strict=True))
    assert not kit.bus.ready() and math.isnan(kit.battery.read())
    # Late events from the old, closed channel objects are not mistaken for the new ones.
    on_library_thread(lambda: (old[0].fire("detach"), old[0].fire("sample", 9.0)))
    kit.bus.tick(1.01, 0.01)
    assert math.isnan(kit.battery.read())
    # The attach timeout counts from the new open, not the first one.
    kit.bus.tick(2.9, 0.01)
    kit.plug_all(button=True)
    kit.bus.tick(3.5, 0.01)
    assert kit.bus.ready() and kit.battery.read() == 2.5 and kit.button.read() is True


# -- digital outputs ---------------------------------------------------------------------------
def test_output_state_is_written_from_the_tick_and_again_on_every_attach() -> None:
    kit = Kit()
    kit.led.write(True)  # before the board is even open
    kit.bus.open(0.0)
    do = kit.handles()[3]
    kit.bus.tick(0.01, 0.01)
    assert do.writes == []  # not attached: nothing to write to
    kit.plug_all()
    assert do.writes == []  # the attach handler itself writes nothing
    kit.bus.tick(0.02, 0.01)
    assert do.writes == [True]
    kit.led.write(False)
    assert do.writes == [True]  # queued, not written from the caller
    kit.bus.tick(0.03, 0.01)
    kit.bus.tick(0.04, 0.01)
    assert do.writes == [True, False]
    # A USB glitch: the library re-attaches the same channel; its state is written again.
    kit.led.write(True)
    kit.bus.tick(0.05, 0.01)
    on_library_thread(lambda: (setattr(do, "attached", False), do.plug()))
    kit.bus.tick(0.06, 0.01)
    assert do.writes == [True, False, True, True]
    # After close and re-open the new channel object gets the commanded state too.
    kit.bus.close()
    kit.bus.open(1.0)
    kit.plug_all()
    kit.bus.tick(1.01, 0.01)
    assert kit.handles()[3].writes == [True]


def test_async_output_writes_retry_after_a_failure() -> None:
    board = FakeBoard(dout=FakeAsyncDigitalOutput)
    bus = PhidgetBus("io", {}, api=board.api)
    led = bus.channel("digital_out", "base.user_led", {"channel": 0})
    bus.open(0.0)
    do = board.of(FakeAsyncDigitalOutput, 0)
    on_library_thread(do.plug)
    led.write(True)
    bus.tick(0.01, 0.01)
    assert [on for on, _ in do.pending] == [True]
    on_library_thread(lambda: do.complete(code=EPHIDGET_NOTATTACHED))
    bus.tick(0.02, 0.01)  # the failure is seen here ...
    bus.tick(0.05, 0.01)
    assert do.pending == []  # ... and the retry waits a little
    bus.tick(0.13, 0.01)
    assert [on for on, _ in do.pending] == [True]
    on_library_thread(do.complete)
    bus.tick(0.2, 0.01)
    bus.tick(0.5, 0.01)
    assert do.writes == [True] and do.pending == []
