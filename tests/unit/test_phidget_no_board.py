"""Issue 19.8: a Phidget bus whose board is not plugged in is reported once as waiting for it
(with the serial numbers it waits for), "back" only on a real attach, and retried quietly.

The first test runs the driver against the official Phidget22 package (in the dev extra):
it opens for real and reports no board, as it does on a machine with none attached."""

from __future__ import annotations

import logging

import pytest

from ramp.clock import VirtualClock
from ramp.hal.phidget import PhidgetBus
from ramp.runtime.buses import BusManager
from ramp.scheduler import Scheduler
from tests.unit.test_phidget_driver import FakeBoard, Kit, on_library_thread


def test_the_real_phidget22_with_no_board_waits_and_never_faults() -> None:
    pytest.importorskip("Phidget22")
    bus = PhidgetBus("sbc_io", {"serial": 300001, "attach_timeout": 0.05})
    bus.channel("digital_in", "base.l_button", {"channel": 0})
    bus.channel("servo", "arm.shoulder", {"channel": 0})
    bus.open(0.0)
    try:
        for i in range(1, 30):
            bus.tick(i * 0.01, 0.01)  # past attach_timeout: no DeviceError
        assert bus.is_open and not bus.ready()
        assert "waiting for its board: Phidget serial 300001" in bus.waiting()
        assert "digital_in 0" in bus.waiting() and "servo 0" in bus.waiting()
    finally:
        bus.close()


def _manager(kit: Kit) -> tuple[BusManager, Scheduler]:
    sched = Scheduler(VirtualClock(), 100.0)
    manager = BusManager({"ble_io": kit.bus}, sched, lambda now: None)
    sched.add_task("buses", 100.0, manager.tick)
    sched.add_task("retry", 1.0, manager.retry)
    manager.start(0.0)
    return manager, sched


def test_an_absent_board_is_reported_once_and_back_only_when_it_attaches(
        caplog: pytest.LogCaptureFixture) -> None:
    kit = Kit(board=FakeBoard(), serial=300001, attach_timeout=2.0)
    manager, sched = _manager(kit)
    with caplog.at_level(logging.DEBUG, logger="ramp.supervisor"):
        sched.run_for(20.0)
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.INFO]
    assert said == [
        "bus ble_io (phidget) waiting for its board: Phidget serial 300001 (analog_in 3 "
        "bridge_in 0 digital_in 1 digital_out 2) is not attached - check the USB cable and "
        "the serial number"]
    assert kit.bus.is_open and not manager.ready("ble_io")
    assert len([h for h in kit.board.created if h.is_open]) == 4  # opened once, kept open
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="ramp.supervisor"):
        kit.plug_all()
        sched.run_for(0.1)
    assert [r.getMessage() for r in caplog.records] == ["bus ble_io is back"]
    assert manager.ready("ble_io")


def test_a_board_with_a_missing_channel_is_still_a_fault() -> None:
    kit = Kit(board=FakeBoard(), attach_timeout=0.5)
    _, sched = _manager(kit)
    ai, br, di, do = kit.handles()
    on_library_thread(lambda: (br.plug(), di.plug(), do.plug()))
    sched.run_for(0.7)
    assert not kit.bus.is_open  # closed by the fault, retried like any hot plug
