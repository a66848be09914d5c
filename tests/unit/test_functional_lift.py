"""ThompsonActuator against a small plant (position integrating the duty, with coasting and
a pot), plus LoadCell calibration and tare. Virtual time: the test steps `now`."""

from __future__ import annotations

import math
import random

import pytest

from ramp.errors import RequestError
from ramp.hal.interfaces import AnalogInput, BridgeInput, MotorChannel
from ramp.layers.functional import LoadCell, Motor
from ramp.modules.thompson_actuator import ThompsonActuator

V0, V1 = 0.8, 4.2  # pot volts at retracted / extended


class FakeMotor(MotorChannel):
    def __init__(self) -> None:
        super().__init__(None, "lift")  # type: ignore[arg-type]

    def _apply(self, duty: float) -> None:
        pass


class FakePot(AnalogInput):
    def __init__(self) -> None:
        super().__init__(None, "pot")  # type: ignore[arg-type]
        self.volts = 0.0
        self.noise = 0.0
        self.rng = random.Random(7)

    def read(self) -> float:
        n = self.rng.uniform(-self.noise, self.noise) if self.noise else 0.0
        return self.volts + n


class Plant:
    """The actuator: speed follows duty * 0.1 stroke/s with a 60 ms lag (it coasts after a
    stop), position clamped to the mechanical ends 0..1, pot linear between V0 and V1."""

    def __init__(self, motor: FakeMotor, pot: FakePot, pos: float, polarity: int = 1) -> None:
        self.motor, self.pot, self.pos, self.polarity = motor, pot, pos, polarity
        self.speed = 0.0
        self.stuck = False
        self.update_pot()

    def update_pot(self) -> None:
        self.pot.volts = V0 + self.pos * (V1 - V0)

    def step(self, dt: float) -> None:
        want = 0.0 if self.stuck else self.polarity * self.motor.duty * 0.1
        self.speed += (want - self.speed) * (1 - math.exp(-dt / 0.06))
        self.pos += self.speed * dt
        if not 0.0 <= self.pos <= 1.0:
            self.pos = min(1.0, max(0.0, self.pos))
            self.speed = 0.0
        self.update_pot()


class Rig:
    """Actuator + plant; runs the plant at 200 Hz and the controller at 50 Hz."""

    def __init__(self, pos: float = 0.5, polarity: int = 1, motor_polarity: int = 1,
                 **kw: float) -> None:
        self.ch = FakeMotor()
        self.pot = FakePot()
        self.plant = Plant(self.ch, self.pot, pos, polarity)
        self.act = ThompsonActuator(Motor(self.ch, polarity=motor_polarity), self.pot,
                                    V0, V1, **kw)
        self.t = 0.0
        self.step = 0
        self.duties: list[float] = []

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds * 200)):
            self.plant.step(0.005)
            self.step += 1
            self.t = self.step * 0.005
            if self.step % 4 == 0:
                self.act.tick(self.t, 0.02)
                self.duties.append(self.ch.duty)

    def reversals(self) -> int:
        signs = [1 if d > 0 else -1 for d in self.duties if d != 0]
        return sum(1 for a, b in zip(signs, signs[1:], strict=False) if a != b)

    def starts(self) -> int:
        return sum(1 for a, b in zip([0.0, *self.duties], self.duties, strict=False)
                   if a == 0 and b != 0)


def test_position_from_pot_calibration() -> None:
    rig = Rig(pos=0.25)
    assert rig.act.position == pytest.approx(0.25)
    rig.pot.volts = V1
    assert rig.act.position == pytest.approx(1.0)
    inverted = ThompsonActuator(Motor(FakeMotor()), rig.pot, 4.0, 1.0)
    rig.pot.volts = 3.25
    assert inverted.position == pytest.approx(0.25)


@pytest.mark.parametrize(("start", "target"), [(0.1, 0.5), (0.9, 0.5), (0.0, 0.75),
                                               (1.0, 0.2), (0.5, 0.55), (0.3, 0.0),
                                               (0.6, 1.0)])
def test_move_reaches_and_holds_without_oscillating(start: float, target: float) -> None:
    rig = Rig(pos=start)
    rig.act.move_to(target)
    assert rig.act.velocity == (100 if target > start else -100)  # starts at once
    rig.run(15.0)
    assert abs(rig.plant.pos - target) <= 0.03
    assert rig.reversals() == 0
    assert rig.starts() == 1
    assert rig.act.velocity == 0
    assert rig.act.is_moving()  # holding
    # only full speed or stop, never a proportional duty
    assert set(rig.duties) <= {0.0, 1.0, -1.0}


def test_move_stops_in_inner_band() -> None:
    rig = Rig(pos=0.2)
    rig.act.move_to(0.6)
    rig.run(8.0)
    assert abs(rig.plant.pos - 0.6) <= 0.012  # within hysteresis + coasting


def test_small_move_inside_tolerance_still_goes_to_target() -> None:
    rig = Rig(pos=0.5)
    rig.act.move_to(0.52)  # inside the 0.03 hold band but outside the 0.01 stop band
    rig.run(2.0)
    assert abs(rig.plant.pos - 0.52) <= 0.012
    rig2 = Rig(pos=0.5)
    rig2.act.move_to(0.505)  # already there
    rig2.run(1.0)
    assert rig2.duties == [0.0] * len(rig2.duties)


def test_hold_recorrects_drift_out_of_band_only() -> None:
    rig = Rig(pos=0.2)
    rig.act.move_to(0.5)
    rig.run(6.0)
    settled = rig.plant.pos
    n = len(rig.duties)
    rig.plant.pos = settled - 0.02  # still inside +-0.03: leave it
    rig.plant.update_pot()
    rig.run(1.0)
    assert set(rig.duties[n:]) == {0.0}
    rig.plant.pos = 0.44  # the load pushed it down out of the band
    rig.plant.update_pot()
    rig.run(2.0)
    assert abs(rig.plant.pos - 0.5) <= 0.012
    assert max(rig.duties[n:]) == 1.0 and min(rig.duties[n:]) == 0.0
    rig.plant.pos = 0.57  # and up
    rig.plant.update_pot()
    rig.run(2.0)
    assert abs(rig.plant.pos - 0.5) <= 0.012
    assert rig.reversals() == 1  # the one needed to come back down


def test_hold_with_noisy_pot_does_not_chatter() -> None:
    rig = Rig(pos=0.1)
    rig.pot.noise = 0.02  # +-0.006 of stroke
    rig.act.move_to(0.6)
    rig.run(20.0)
    assert abs(rig.plant.pos - 0.6) <= 0.03
    assert rig.starts() <= 2
    assert rig.reversals() == 0


def test_extend_and_retract_run_to_the_ends() -> None:
    rig = Rig(pos=0.3)
    rig.act.extend()
    assert rig.act.velocity == 100
    rig.run(9.0)
    assert rig.plant.pos >= 0.99
    assert rig.act.velocity == 0 and rig.ch.duty == 0.0
    assert not rig.act.is_moving()
    assert not rig.act.stalled  # the end is not a stall
    rig.act.retract()
    assert rig.act.velocity == -100
    rig.run(12.0)
    assert rig.plant.pos <= 0.01
    assert rig.act.velocity == 0 and not rig.act.is_moving()
    assert set(rig.duties) <= {0.0, 1.0, -1.0}


def test_extend_at_the_end_does_nothing() -> None:
    rig = Rig(pos=0.995)
    rig.act.extend()
    assert rig.act.velocity == 0 and not rig.act.is_moving()


def test_manual_vel_stops_at_an_end_and_reports_zero() -> None:
    rig = Rig(pos=0.9)
    rig.act.vel(40)
    assert rig.act.velocity == 40 and rig.ch.duty == pytest.approx(0.4)
    rig.run(5.0)
    assert rig.plant.pos >= 0.99
    assert rig.act.velocity == 0 and not rig.act.is_moving() and not rig.act.stalled
    rig.act.vel(30)  # further into the end: refused quietly
    assert rig.act.velocity == 0
    rig.act.vel(-30)
    assert rig.act.velocity == -30


def test_new_command_cancels_a_move() -> None:
    rig = Rig(pos=0.2)
    rig.act.move_to(0.9)
    rig.run(1.0)
    rig.act.vel(-50)  # manual overrides the move
    assert rig.act.mode == "manual" and rig.act.target is None
    assert rig.ch.duty == pytest.approx(-0.5)
    rig.run(0.5)
    assert rig.act.velocity == -50
    rig.act.retract()
    rig.run(0.1)
    assert rig.act.velocity == -100
    here = rig.plant.pos
    rig.act.move_to(min(1.0, here + 0.3))  # reversal passes through rest
    assert rig.act.velocity == 0
    rig.run(0.04)
    assert rig.act.velocity == 100
    rig.act.stop()
    assert rig.act.velocity == 0 and not rig.act.is_moving()
    rig.run(1.0)
    assert set(rig.duties[-50:]) == {0.0}


def test_stall_fault_latched_and_cleared_by_stop() -> None:
    rig = Rig(pos=0.4)
    rig.plant.stuck = True
    rig.act.extend()
    rig.run(1.4)
    assert not rig.act.stalled and rig.act.velocity == 100
    rig.run(0.3)
    assert rig.act.stalled
    assert rig.act.fault.startswith("lift stalled: ")
    assert "up" in rig.act.fault
    assert rig.ch.duty == 0.0 and rig.act.velocity == 0 and not rig.act.is_moving()
    for cmd in (rig.act.extend, rig.act.retract, lambda: rig.act.move_to(0.2),
                lambda: rig.act.vel(20)):
        with pytest.raises(RequestError) as e:
            cmd()
        assert e.value.code == "fault"
        assert e.value.detail.startswith("lift stalled: ")
    rig.act.vel(0)  # harmless: accepted, does not clear
    assert rig.act.stalled
    rig.run(1.0)
    assert set(rig.duties[-50:]) == {0.0}  # stays stopped
    rig.act.stop()  # a watchdog trip or takeover does not clear the latch ...
    assert rig.act.stalled
    rig.act.clear_fault()  # ... the operator's explicit module stop does
    assert not rig.act.stalled
    rig.plant.stuck = False
    rig.act.extend()
    rig.run(8.0)
    assert rig.plant.pos >= 0.99 and not rig.act.stalled


def test_stall_while_holding() -> None:
    rig = Rig(pos=0.2)
    rig.act.move_to(0.8)
    rig.run(1.0)
    rig.plant.stuck = True
    rig.run(2.0)
    assert rig.act.stalled and rig.ch.duty == 0.0 and rig.act.mode == "idle"


def test_wrong_polarity_is_caught_as_a_stall() -> None:
    rig = Rig(pos=0.5, polarity=-1)  # motor wired backwards, YAML not told
    rig.act.move_to(0.8)
    rig.run(3.0)
    assert rig.act.stalled
    assert "wrong way" in rig.act.fault
    assert rig.plant.pos > 0.3  # stopped before running into the end


def test_motor_polarity_fixes_a_reversed_motor() -> None:
    rig = Rig(pos=0.5, polarity=-1, motor_polarity=-1)
    rig.act.move_to(0.8)
    rig.run(6.0)
    assert abs(rig.plant.pos - 0.8) <= 0.03 and not rig.act.stalled


def test_slow_manual_drive_is_not_a_stall() -> None:
    rig = Rig(pos=0.3)
    rig.act.vel(5)  # 0.005 stroke/s: 0.0075 in the stall time, under the full-speed 0.01
    rig.run(5.0)
    assert not rig.act.stalled and rig.act.velocity == 5
    rig.plant.stuck = True  # but a slow drive that does not move at all still stalls
    rig.run(2.0)
    assert rig.act.stalled


def test_config_checks() -> None:
    with pytest.raises(ValueError):
        ThompsonActuator(Motor(FakeMotor()), FakePot(), 1.0, 1.0)
    with pytest.raises(ValueError):
        ThompsonActuator(Motor(FakeMotor()), FakePot(), 0.0, 5.0, tolerance=0.03,
                         hysteresis=0.05)


# -- LoadCell -----------------------------------------------------------------------------------
class FakeBridge(BridgeInput):
    def __init__(self, ratio: float) -> None:
        super().__init__(None, "cell")  # type: ignore[arg-type]
        self.ratio = ratio

    def read(self) -> float:
        return self.ratio


def test_load_cell_calibration() -> None:
    cell = LoadCell(FakeBridge(0.5), kg_per_mv_v=100.0, offset_mv_v=0.1)
    assert cell.kg == pytest.approx(40.0)
    cell.channel.ratio = 0.1  # type: ignore[attr-defined]
    assert cell.kg == pytest.approx(0.0)
    neg = LoadCell.from_params(FakeBridge(-0.2), {"kg_per_mv_v": -50.0, "offset_mv_v": 0.0})
    assert neg.kg == pytest.approx(10.0)


def test_load_cell_tare() -> None:
    bridge = FakeBridge(0.37)
    cell = LoadCell(bridge, kg_per_mv_v=80.0)
    assert cell.kg == pytest.approx(29.6)
    cell.tare()
    assert cell.kg == pytest.approx(0.0)
    bridge.ratio = 0.37 + 0.125
    assert cell.kg == pytest.approx(10.0)
    with pytest.raises(ValueError):
        LoadCell(bridge, kg_per_mv_v=0.0)
