"""The simulated world made of parts (firmware_like/world.py, SPEC 10): signals routed to the
part that owns them, plain signals for the rest, the sim module's input overrides through a
part's sensor model, parts a chassis carries stepped by it alone, and MARTE's BLE as a part."""

from __future__ import annotations

import pytest

from firmware_like.bucket_ladder import BucketLadderExcavator
from firmware_like.marte import MarteWorld
from firmware_like.world import World


class Lamp:
    """A part owning `m.lamp` (an output) and `m.switch` (an input), counting its steps."""

    def __init__(self) -> None:
        self.on = False
        self.steps = 0
        self.revision = 0

    def _own(self, name: str, device: str) -> None:
        if name != f"m.{device}":
            raise KeyError(name)

    def write_digital(self, name: str, on: bool) -> None:
        self._own(name, "lamp")
        self.on = on

    def read_digital(self, name: str) -> bool:
        self._own(name, "switch")
        return self.on

    def sensor_reading(self, name: str, quantity: float) -> bool:
        self._own(name, "switch")
        return quantity > 0.5

    def step(self, dt: float) -> None:
        self.steps += 1
        self.revision += 1


def test_signals_go_to_their_part_and_the_rest_are_plain() -> None:
    lamp = Lamp()
    w = World([lamp])
    w.write_digital("m.lamp", True)
    assert lamp.on and w.read_digital("m.switch")
    w.set_motor("other.motor", 0.5)  # no part owns it
    assert w.plain.motors == {"other.motor": 0.5}
    assert w.read_analog("other.sensor") == 0.0


def test_an_override_reads_through_the_part_s_sensor_and_moves_the_revision() -> None:
    lamp = Lamp()
    w = World([lamp])
    before = w.revision
    w.set_input("m.switch", 0.9)
    assert w.revision != before
    assert w.read_digital("m.switch") is True and not lamp.on
    w.clear_input("m.switch")
    assert w.read_digital("m.switch") is False


def test_a_part_added_twice_is_stepped_once_and_a_carried_part_not_at_all() -> None:
    lamp = Lamp()
    marte = MarteWorld()
    w = World([lamp, lamp, marte, marte.ble])
    assert w.parts == [lamp, marte, marte.ble]
    assert not hasattr(marte.ble, "step")
    w.step(0.1)
    assert lamp.steps == 1 and marte.time == pytest.approx(0.1)


def test_an_unplugged_bus_is_absent_until_replugged() -> None:
    w = World([Lamp()])
    w.unplug("io")
    assert not w.bus_present("io") and w.bus_present("other")
    w.replug("io")
    assert w.bus_present("io")


def test_marte_s_ble_is_its_own_part_read_through_the_robot() -> None:
    marte = MarteWorld()
    assert isinstance(marte.ble, BucketLadderExcavator)
    marte.set_motor("ble.lift_motor", 1.0)
    assert marte.ble.duty["ble.lift_motor"] == 1.0 and marte.duty("ble.lift_motor") == 1.0
    marte.step(2.0)
    assert marte.lift_pos == marte.ble.lift_pos > 0.1
    assert marte.battery_current > marte.params.idle_current  # the BLE loads the battery
