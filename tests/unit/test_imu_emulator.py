"""The PhidgetSpatial emulator: physics, the board's conventions, noise, and the two faults."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest

from firmware_like.imu import GRAVITY_MPS2, ImuEmulator, ImuModel, ImuTruth, SpatialData
from ramp.autonomy.mount import Mount, angle_between, mat_vec, transpose
from ramp.clock import VirtualClock

QUIET = ImuModel(accel_noise_g=0.0, gyro_noise_dps=0.0, mag_noise_gauss=0.0, accel_bias_g=0.0,
                 gyro_bias_dps=0.0)


@dataclass
class Chassis:
    """A truth source the tests steer by hand (the arena world's `imu_truth()` stands here)."""

    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    omega_body: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_body: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __call__(self) -> Chassis:
        return self


def run(emu: ImuEmulator, clock: VirtualClock, seconds: float, step: float = 0.01
        ) -> list[SpatialData]:
    out: list[SpatialData] = []
    for _ in range(round(seconds / step)):
        clock.advance(step)
        out += emu.poll()
    return out


def mean(samples: list[SpatialData], field: str) -> tuple[float, float, float]:
    vs = [getattr(s, field) for s in samples]
    return tuple(sum(v[i] for v in vs) / len(vs) for i in range(3))  # type: ignore[return-value]


def integrate(samples: list[SpatialData], dt: float) -> tuple[float, float, float]:
    return tuple(sum(s.angular_rate[i] for s in samples) * dt
                 for i in range(3))  # type: ignore[return-value]


def test_at_rest_and_level_it_reads_one_g_along_its_up_axis() -> None:
    clock = VirtualClock()
    emu = ImuEmulator(clock, Chassis(), seed=1)
    samples = run(emu, clock, 2.0)
    ax, ay, az = mean(samples, "acceleration")
    # Phidget22's sign: lying level the board reads -1 g on z. Bias sigma is 2 mg.
    assert az == pytest.approx(-1.0, abs=0.01)
    assert abs(ax) < 0.01 and abs(ay) < 0.01
    gx, gy, gz = mean(samples, "angular_rate")
    assert max(abs(gx), abs(gy), abs(gz)) < 0.25  # bias sigma 0.05 deg/s, 5 sigma


@pytest.mark.parametrize("mount", [Mount(roll=90.0), Mount(pitch=-30.0, yaw=45.0),
                                   Mount(roll=180.0, yaw=90.0), Mount(roll=20, pitch=35, yaw=-120)])
def test_gravity_is_seen_through_the_mount_rotation(mount: Mount) -> None:
    clock = VirtualClock()
    emu = ImuEmulator(clock, Chassis(), seed=2, mount=mount, model=QUIET)
    (s,) = run(emu, clock, 0.008, step=0.008)
    up_in_sensor = mat_vec(transpose(mount.rotation()), (0.0, 0.0, 1.0))
    assert s.acceleration == pytest.approx(tuple(-u for u in up_in_sensor), abs=1e-12)


def test_samples_come_every_data_interval_with_the_boards_timestamp() -> None:
    clock = VirtualClock(100.0)
    emu = ImuEmulator(clock, Chassis(), data_interval_ms=8)
    samples = run(emu, clock, 1.0)
    assert len(samples) == 125
    assert [s.timestamp_ms for s in samples[:3]] == [8.0, 16.0, 24.0]
    assert samples[-1].t == pytest.approx(101.0)
    assert all(b.t - a.t == pytest.approx(0.008) for a, b in zip(samples, samples[1:],
                                                                  strict=False))
    emu.set_data_interval(4)
    more = run(emu, clock, 0.1)
    assert len(more) == 25 and more[0].timestamp_ms == 1004.0


def test_a_known_rotation_rate_reads_back_in_the_boards_axes() -> None:
    clock = VirtualClock()
    chassis = Chassis(omega_body=(0.1, -0.2, math.radians(30.0)))
    emu = ImuEmulator(clock, chassis, mount=Mount(yaw=90.0), model=QUIET)
    samples = run(emu, clock, 0.5)
    # The board is turned 90 deg left: its x is the chassis' y, its y the chassis' -x.
    for s in samples:
        assert s.angular_rate == pytest.approx(
            (math.degrees(-0.2), -math.degrees(0.1), 30.0), abs=1e-9)


def test_a_pitched_chassis_tips_gravity_toward_the_boards_x() -> None:
    clock = VirtualClock()
    emu = ImuEmulator(clock, Chassis(pitch=math.radians(10.0)), model=QUIET)
    (s,) = run(emu, clock, 0.008, step=0.008)
    # Nose down: the specific force (up) leans back along -x; the board reports its negative.
    assert s.acceleration == pytest.approx((math.sin(math.radians(10)), 0.0,
                                            -math.cos(math.radians(10))), abs=1e-12)


def test_motion_and_the_lever_arm_add_to_the_specific_force() -> None:
    clock = VirtualClock()
    chassis = Chassis(omega_body=(0.0, 0.0, 2.0), accel_body=(1.0, 0.0, 0.0))
    emu = ImuEmulator(clock, chassis, mount=Mount(x=0.5), model=QUIET)
    (s,) = run(emu, clock, 0.008, step=0.008)
    # forward 1 m/s^2, centripetal -w^2 r = -2 m/s^2 along x at 0.5 m from the spin axis
    assert s.acceleration[0] == pytest.approx(-(1.0 - 2.0) / GRAVITY_MPS2, abs=1e-12)
    assert s.acceleration[2] == pytest.approx(-1.0, abs=1e-12)


def test_truth_is_interpolated_between_polls() -> None:
    clock = VirtualClock()
    chassis = Chassis()
    emu = ImuEmulator(clock, chassis, model=QUIET, data_interval_ms=2)
    run(emu, clock, 0.1, step=0.1)
    chassis.omega_body = (0.0, 0.0, 1.0)
    samples = run(emu, clock, 0.1, step=0.1)
    rates = [s.angular_rate[2] for s in samples]
    assert rates == sorted(rates) and rates[-1] == pytest.approx(math.degrees(1.0))
    assert rates[24] == pytest.approx(math.degrees(0.5), rel=1e-9)


def test_same_seed_same_samples_however_the_polls_fall() -> None:
    def samples(seed: int, step: float, fault: str) -> list[SpatialData]:
        clock = VirtualClock()
        emu = ImuEmulator(clock, lambda: ImuTruth(pitch=0.05), seed=seed, fault=fault,
                          shift_window_s=(0.5, 1.5))
        return run(emu, clock, 2.0, step=step)

    a = samples(7, 0.01, "imu-shift")
    assert a == samples(7, 0.05, "imu-shift")
    assert a != samples(8, 0.01, "imu-shift")
    # Noise is drawn per sample whatever the fault, so faults can be compared seed to seed.
    plain = samples(7, 0.01, "none")
    assert a[:60] == plain[:60]


def test_gyro_drift_integrates_to_several_degrees_per_minute() -> None:
    for seed in range(3):
        clock = VirtualClock()
        drifting = ImuEmulator(clock, Chassis(), seed=seed, fault="gyro-drift")
        healthy = ImuEmulator(clock, Chassis(), seed=seed)
        d_run, h_run = [], []
        for _ in range(12000):  # two minutes at rest
            clock.advance(0.01)
            d_run += drifting.poll()
            h_run += healthy.poll()
        # The drift alone (same seed: same noise and bias) over the second minute:
        half = len(d_run) // 2
        d = integrate(d_run[half:], 0.008)
        h = integrate(h_run[half:], 0.008)
        drift = [abs(d[i] - h[i]) for i in range(3)]
        assert all(2.0 < x < 12.0 for x in drift), (seed, drift)
        # ... and it wanders: it is not there at start-up, so a start-up zeroing misses it.
        first = integrate(d_run[:125], 0.008)
        first_h = integrate(h_run[:125], 0.008)
        assert all(abs(first[i] - first_h[i]) < 0.05 for i in range(3))
        assert drifting.fault_info()["fault"] == "gyro-drift"


def test_imu_shift_tilts_gravity_4_to_8_degrees_at_the_chosen_moment_and_not_before() -> None:
    moments = set()
    for seed in range(6):
        clock = VirtualClock()
        emu = ImuEmulator(clock, Chassis(), seed=seed, fault="imu-shift", model=QUIET,
                          shift_window_s=(5.0, 20.0))
        info = emu.fault_info()
        at = emu.shift_at_s
        assert 5.0 <= info["at_s"] <= 20.0 and at == pytest.approx(info["at_s"], abs=1e-3)
        assert 4.0 <= emu.shift_deg <= 8.0 and emu.shift_axis[2] == 0.0  # horizontal axis
        moments.add(round(at, 3))
        before = run(emu, clock, at - 0.01)
        rest = (0.0, 0.0, -1.0)
        assert max(angle_between(s.acceleration, rest) for s in before) < 1e-9
        after = run(emu, clock, 1.0)
        settled = [s for s in after if s.t > at + emu.model.shift_duration_s]
        tilt = math.degrees(angle_between(settled[-1].acceleration, rest))
        assert tilt == pytest.approx(emu.shift_deg, abs=1e-6)
        # While the mount gives way the gyro sees it turn.
        moving = [s for s in after if at < s.t < at + emu.model.shift_duration_s]
        assert moving and max(math.hypot(*s.angular_rate) for s in moving) > 10.0
    assert len(moments) == 6  # the seed picks the moment


def test_an_unplugged_board_sends_nothing_and_restarts_its_timestamp() -> None:
    clock = VirtualClock()
    emu = ImuEmulator(clock, Chassis())
    run(emu, clock, 1.0)
    emu.unplug()
    assert run(emu, clock, 0.5) == []
    emu.plug()
    back = run(emu, clock, 0.1)
    assert back[0].timestamp_ms == 8.0 and back[0].t == pytest.approx(1.508)


def test_zero_gyro_removes_the_bias_measured_while_still() -> None:
    clock = VirtualClock()
    emu = ImuEmulator(clock, Chassis(), seed=4, model=ImuModel(gyro_bias_dps=0.5))
    biased = mean(run(emu, clock, 1.0), "angular_rate")
    assert max(abs(b) for b in biased) > 0.2
    emu.zero_gyro()
    run(emu, clock, 2.5)
    zeroed = mean(run(emu, clock, 2.0), "angular_rate")
    assert max(abs(z) for z in zeroed) < 0.03


def test_unknown_faults_and_intervals_are_refused() -> None:
    with pytest.raises(ValueError, match="gyro-drift, imu-shift"):
        ImuEmulator(VirtualClock(), Chassis(), fault="imu-melt")
    with pytest.raises(ValueError, match="data interval"):
        ImuEmulator(VirtualClock(), Chassis(), data_interval_ms=0)
