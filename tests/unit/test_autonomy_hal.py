"""The autonomy's HAL interfaces through the `sim` drivers bound to their emulators."""

from __future__ import annotations

import math

import pytest

from firmware_like.imu import ImuEmulator, ImuTruth
from firmware_like.servo import gimbal_emulator
from ramp.autonomy.config import GimbalConfig, ImuConfig, ServoConfig
from ramp.autonomy.hal import DRIVERS, driver_class
from ramp.autonomy.hal.interfaces import Imu, ImuSample, PanTilt
from ramp.autonomy.hal.sim import SimImu, SimPanTilt
from ramp.clock import VirtualClock
from ramp.errors import DeviceError
from ramp.scheduler import Scheduler

GIMBAL = GimbalConfig(pan=ServoConfig("pan", 0, -90.0, 90.0, velocity_dps=90.0),
                      tilt=ServoConfig("tilt", 1, -30.0, 45.0, velocity_dps=60.0))


def sim_imu(clock: VirtualClock, interval_ms: int = 8) -> tuple[SimImu, ImuEmulator]:
    emu = ImuEmulator(clock, lambda: ImuTruth(), seed=3)
    return SimImu(ImuConfig(driver="sim", data_interval_ms=interval_ms), emulator=emu), emu


def sim_gimbal(clock: VirtualClock) -> SimPanTilt:
    return SimPanTilt(GIMBAL, emulator=gimbal_emulator(clock, GIMBAL))


# -- registry ----------------------------------------------------------------------------------
@pytest.mark.parametrize(("kind", "base"), [("imu", Imu), ("gimbal", PanTilt)])
def test_every_registered_driver_implements_its_interface_under_its_name(
        kind: str, base: type) -> None:
    assert set(DRIVERS[kind]) == {"phidget", "sim"}
    for name in DRIVERS[kind]:
        cls = driver_class(kind, name)
        assert issubclass(cls, base) and cls.driver_name == name


def test_unknown_names_list_the_valid_ones() -> None:
    with pytest.raises(ValueError, match=r"unknown imu driver 'xsens' \(expected one of: "
                                         r"phidget, sim\)"):
        driver_class("imu", "xsens")
    with pytest.raises(ValueError,
                       match=r"unknown lidar driver 'sick' \(expected one of: hokuyo\)"):
        driver_class("lidar", "sick")
    with pytest.raises(ValueError, match="expected one of: gimbal, imu, lidar"):
        driver_class("radar", "sim")


def test_the_lidar_is_registered_under_its_driver_name() -> None:
    from ramp.autonomy.hal.lidar import Lidar

    assert issubclass(driver_class("lidar", "hokuyo"), Lidar)


# -- IMU ---------------------------------------------------------------------------------------
def test_imu_samples_flow_through_scheduler_ticks_on_the_virtual_clock() -> None:
    clock = VirtualClock()
    imu, _emu = sim_imu(clock)
    sched = Scheduler(clock, rate_hz=100.0)
    imu.open(clock.now())
    got: list[ImuSample] = []
    sched.add_task("imu", 100.0, imu.tick)
    sched.add_task("reader", 50.0, lambda now, dt: got.extend(imu.drain()))
    sched.run_for(1.0)
    imu.tick(clock.now(), 0.0)
    got += imu.drain()
    assert imu.ready() and 120 <= len(got) <= 126
    assert [s.timestamp_ms for s in got] == [8.0 * (i + 1) for i in range(len(got))]
    s = got[-1]
    assert s.specific_force_g[2] == pytest.approx(1.0, abs=0.01)
    assert s.gyro_rad_s[2] == pytest.approx(math.radians(s.gyro_dps[2]))


def test_an_unplugged_imu_is_a_fault_until_it_comes_back() -> None:
    clock = VirtualClock()
    imu, emu = sim_imu(clock)
    imu.open(0.0)
    clock.advance(0.1)
    imu.tick(clock.now(), 0.1)
    assert imu.ready()
    emu.unplug()
    clock.advance(0.1)
    imu.tick(clock.now(), 0.1)
    assert isinstance(imu.fault, DeviceError) and not imu.ready()
    assert "detached" in str(imu.fault) and str(imu.fault).startswith("bus imu")
    emu.plug()
    clock.advance(0.1)
    imu.tick(clock.now(), 0.1)
    assert imu.ready() and imu.drain()[-1].timestamp_ms == 96.0


def test_a_slow_reader_loses_the_oldest_samples_and_they_are_counted() -> None:
    clock = VirtualClock()
    imu, _emu = sim_imu(clock, interval_ms=1)
    imu.open(0.0)
    clock.advance(5.0)
    imu.tick(clock.now(), 5.0)
    got = imu.drain()
    assert len(got) == Imu.MAX_BUFFER and imu.dropped == 5000 - Imu.MAX_BUFFER
    assert got[-1].timestamp_ms == 5000.0


def test_imu_close_is_idempotent_and_a_closed_imu_ignores_ticks() -> None:
    clock = VirtualClock()
    imu, _emu = sim_imu(clock)
    with imu:
        imu.open(0.0)
        imu.open(0.0)
    imu.close()
    clock.advance(1.0)
    imu.tick(clock.now(), 1.0)
    assert imu.drain() == [] and not imu.is_open


# -- gimbal ------------------------------------------------------------------------------------
def test_servo_commands_are_checked_and_a_bad_one_changes_nothing() -> None:
    g = sim_gimbal(VirtualClock())
    for bad in (float("nan"), float("inf"), "10", True, 46.0, -31.0):
        with pytest.raises(ValueError, match="gimbal.tilt"):
            g.point(0.0, bad)  # type: ignore[arg-type]
    assert g.pan.target_deg is None and g.tilt.target_deg is None  # pan untouched too
    with pytest.raises(ValueError, match="set a target before engaging"):
        g.engage()
    assert not g.pan.engaged
    for bad_v in (0.0, -5.0, 5000.0, float("nan")):
        with pytest.raises(ValueError, match="velocity limit"):
            g.pan.set_velocity_limit(bad_v)
    with pytest.raises(ValueError, match="acceleration"):
        g.pan.set_acceleration(0.0)
    assert g.pan.velocity_limit_dps == 90.0
    assert g.tilt.clamp(80.0) == 45.0 and g.tilt.clamp(-80.0) == -30.0
    assert g.tilt.limits == (-30.0, 45.0)


def test_the_gimbal_moves_at_its_speed_and_reports_reaching_the_target() -> None:
    clock = VirtualClock()
    g = sim_gimbal(clock)
    g.open(0.0)
    g.point(0.0, 0.0)
    g.engage()
    g.tick(0.0, 0.0)
    assert g.reached and g.angles() == (0.0, 0.0)
    g.point(45.0, -20.0)
    assert not g.reached
    clock.advance(0.3)
    g.tick(clock.now(), 0.3)
    pan, tilt = g.angles()
    assert pan is not None and tilt is not None and 0.0 < pan < 45.0 and -20.0 < tilt < 0.0
    clock.advance(1.0)
    g.tick(clock.now(), 1.0)
    assert g.angles() == (45.0, -20.0) and g.reached
    assert g.emulator.angles() == (45.0, -20.0)  # where the ray-caster puts the LIDAR


def test_a_gimbal_that_comes_back_gets_every_command_again() -> None:
    clock = VirtualClock()
    g = sim_gimbal(clock)
    g.point(10.0, 5.0)  # before open: recorded
    g.engage()
    g.open(0.0)
    g.tick(0.0, 0.0)
    assert g.emulator.pan.engaged and g.emulator.pan.target_deg == 10.0
    g.emulator.unplug()
    clock.advance(0.1)
    g.tick(clock.now(), 0.1)
    assert isinstance(g.fault, DeviceError) and g.pan.position_deg is None
    g.tilt.set_target(20.0)  # while away: recorded
    g.emulator.plug()
    clock.advance(0.1)
    g.tick(clock.now(), 0.1)
    assert g.fault is None and g.ready()
    assert g.emulator.tilt.target_deg == 20.0 and g.emulator.tilt.engaged
    g.engage(False)
    assert not g.emulator.pan.engaged and g.pan.position_deg is None
