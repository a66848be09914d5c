"""The simulation rig: the world, the emulators and the autonomy's real drivers on one virtual
clock; the scan records it produces lie where the world really is; a backend attached moves
the same world on commands sent over MCP."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest

from firmware_like.lidar_view import LidarView
from firmware_like.marte import MarteWorld
from ramp.autonomy.hal.lidar import Scan, ScanGeometry
from ramp.autonomy.mcp_link import McpLink
from ramp.autonomy.mount import Mount
from ramp.autonomy.perception.cloud import plan_sweep
from ramp.autonomy.perception.records import ScanRecord
from ramp.autonomy.perception.sweep import DONE, Sweep
from ramp.simulation.backend import SimBackend
from ramp.simulation.rig import Rig, load_autonomy_config, shift_window

ARENA = (7.38, 3.88)


@pytest.fixture
def rig() -> Iterator[Rig]:
    world = MarteWorld.seeded(3)
    world.place(1.0, 1.2, 20.0)  # on the seeded ground: the chassis is not level
    with Rig(world, seed=3) as r:
        yield r


def wall_distance(points: np.ndarray) -> np.ndarray:
    x, y = points[:, 0], points[:, 1]
    return np.minimum.reduce([np.abs(x), np.abs(ARENA[0] - x), np.abs(y), np.abs(ARENA[1] - y)])


def arena_points(records: list[ScanRecord], world: MarteWorld) -> np.ndarray:
    return np.concatenate([r.points_arena(world.x, world.y, world.yaw, world.z)
                           for r in records])


class _HornsAt:
    """A gimbal whose horns stand where the test puts them (the emulator's own class may be
    compiled, so its methods cannot be replaced on the instance)."""

    def __init__(self, pan: float, tilt: float) -> None:
        self.pan, self.tilt = pan, tilt

    def angles(self) -> tuple[float, float]:
        return (self.pan, self.tilt)


def test_the_simulators_lidar_and_autonomy_yaml_agree_on_where_the_scanner_is() -> None:
    world = MarteWorld.seeded(1)
    world.place(2.0, 1.0, 35.0)
    view = LidarView.of(world)  # firmware_like's own mount, as `ramp sim lidar` uses it
    with Rig(world, load_autonomy_config()) as rig:
        for pan, tilt in ((0.0, 0.0), (30.0, 10.0), (-60.0, 40.0), (90.0, -20.0)):
            rig.sensors.gimbal_emulator = _HornsAt(pan, tilt)  # type: ignore[assignment]
            ours = rig.true_lidar_pose()
            theirs = view.pose_of_world(math.radians(pan), math.radians(tilt))
            assert ours.origin == pytest.approx(theirs.origin, abs=1e-9)
            assert ours.rotation == pytest.approx(theirs.rotation, abs=1e-9)


def test_a_config_with_another_mount_moves_the_simulated_scanner_with_it() -> None:
    world = MarteWorld()
    cfg = load_autonomy_config()
    cfg = replace(cfg, lidar=replace(cfg.lidar, mount=Mount(0.5, 0.1, 0.6)),
                  gimbal=replace(cfg.gimbal, pivot=(0.5, 0.1, 0.5)))
    with Rig(world, cfg) as rig:
        rig.sensors.gimbal_emulator = _HornsAt(0.0, 90.0)  # type: ignore[assignment]
        pose = rig.true_lidar_pose()  # tilted straight down about a pivot 10 cm below
        c = world.chassis_pose()
        expected = (c.x + 0.5 * math.cos(c.yaw) + 0.1 * -math.sin(c.yaw) + 0.1 * math.cos(c.yaw),
                    c.y + 0.5 * math.sin(c.yaw) + 0.1 * math.cos(c.yaw) + 0.1 * math.sin(c.yaw),
                    c.z + 0.5)
        assert pose.origin == pytest.approx(expected, abs=1e-9)


def test_the_drivers_come_up_and_every_scan_record_lies_on_the_walls(rig: Rig) -> None:
    assert rig.run_until(lambda: rig.perception.ready, 5.0)
    assert rig.lidar.state == "streaming" and rig.imu.ready() and rig.pan_tilt.ready()
    start = rig.clock.now()
    rig.run_for(1.0)
    records = rig.scans.since(start)
    assert 38 <= len(records) <= 41  # 40 scans a second, through SCIP over TCP
    world = rig.world
    assert abs(world.pitch) + abs(world.roll) > math.radians(0.3)  # the gimbal has work
    for r in records:
        assert r.tilt_deg == pytest.approx(rig.leveller.target[1], abs=0.05)  # type: ignore[index]
        assert math.degrees(abs(r.pitch - world.pitch)) < 0.3
        assert math.degrees(abs(r.roll - world.roll)) < 0.3
    pts = arena_points(records, world)
    on_wall = wall_distance(pts) < 0.05
    assert on_wall.mean() > 0.9  # the rest: the robot's own frame posts and dust
    assert float(np.median(wall_distance(pts[on_wall]))) < 0.015
    # and level: wall hits at the scanner's height, all round the arena
    lidar_z = rig.true_lidar_pose().origin[2]
    assert float(np.median(np.abs(pts[on_wall, 2] - lidar_z))) < 0.03


def test_a_stop_and_go_sweep_keeps_one_whole_scan_per_tilt_on_the_true_surface(
        rig: Rig) -> None:
    assert rig.run_until(lambda: rig.perception.ready, 5.0)
    cfg = rig.config
    plan = plan_sweep(cfg.lidar.mount, cfg.gimbal.pivot, near_m=1.0, far_m=2.5, spacing_m=0.1,
                      tilt_max_deg=75.0)
    sweep = Sweep(rig.leveller, rig.scans, rig.pan_tilt, plan, ahrs=rig.ahrs)
    horn: list[tuple[float, float]] = []  # the servo's true tilt, every tick
    tasks = [rig.scheduler.add_task("sweep", rig.scheduler.rate_hz, sweep.tick),
             rig.scheduler.add_task("horn", rig.scheduler.rate_hz,
                                    lambda now, dt: horn.append(
                                        (now, rig.gimbal_emulator.angles()[1])))]
    sweep.start(rig.clock.now())
    assert rig.run_until(lambda: sweep.finished, plan.duration_s + 1.0)
    for task in tasks:
        rig.scheduler.remove_task(task)
    assert sweep.state == DONE and not sweep.saturated and not sweep.attitude_changed
    assert len(sweep.records) == plan.scans == 16
    world = rig.world
    for record, tilt in zip(sweep.records, plan.tilts_deg, strict=True):
        # the servo took the chassis' pitch out: the plan's tilts are below the horizon
        assert record.tilt_deg + math.degrees(world.pitch) == pytest.approx(tilt, abs=0.3)
        assert record.started is not None
        end = record.started + 0.01875  # 1081 steps of 1440 at 25 ms a turn
        before = max(t for t, _ in horn if t <= record.started)
        after = min(t for t, _ in horn if t >= end)
        during = [a for t, a in horn if before <= t <= after]
        assert max(during) - min(during) < 0.01  # the gimbal stood still all through the scan
    times = [r.t for r in sweep.records]
    assert all(b - a >= 0.025 for a, b in zip(times, times[1:], strict=False))
    pts = arena_points(sweep.records, world)
    scanner = rig.true_lidar_pose().origin
    off_robot = np.hypot(pts[:, 0] - scanner[0], pts[:, 1] - scanner[1]) > 0.8  # frame posts
    inside = (wall_distance(pts) > 0.05) & off_robot
    ground = world.terrain.height(pts[inside, 0], pts[inside, 1])
    err = np.abs(pts[inside, 2] - ground)
    assert inside.sum() > 5_000
    assert float(np.median(err)) < 0.01 and float(np.mean(err < 0.05)) > 0.98
    assert rig.run_until(lambda: rig.leveller.settled, 3.0)  # level again afterwards
    assert rig.leveller.wanted_tilt_deg == 0.0


def test_the_same_seed_gives_the_same_run() -> None:
    def run() -> tuple[list[np.ndarray], tuple[float, float, float]]:
        world = MarteWorld.seeded(8)
        with Rig(world, seed=8, fault="gyro-drift") as rig:
            rig.run_for(3.0)
            return [r.ranges for r in list(rig.scans.records)[-5:]], rig.ahrs.attitude

    a, b = run(), run()
    assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a[0], b[0], strict=True))
    assert a[1] == b[1]


def test_the_imu_shift_falls_inside_the_run_and_bad_faults_are_refused() -> None:
    assert shift_window(600.0) == (60.0, 540.0)
    world = MarteWorld()
    with Rig(world, seed=2, fault="imu-shift", run_length_s=20.0) as rig:
        at = rig.imu_emulator.fault_info()["at_s"]
        assert 2.0 <= at <= 18.0
    with pytest.raises(ValueError, match="unknown fault"):
        Rig(world, fault="gps-jam")


def test_scan_time_is_the_front_beams_moment_on_the_host_clock(rig: Rig) -> None:
    g = ScanGeometry()

    def scan(sensor_time: float, received_at: float) -> Scan:
        return Scan.from_raw(np.full(1081, 2000), g, sensor_time=sensor_time,
                             received_at=received_at)

    c = rig.scans
    ready = 1081 / 1440 * 0.025  # step 1080 measured: the scan's data is complete
    front = 540 / 1440 * 0.025  # step 540, straight ahead
    assert c.scan_time(scan(10.0, 110.030)) == pytest.approx(110.030 - ready + front, abs=1e-6)
    # a scan that came faster shows the least delay; one that came late does not move it
    assert c.scan_time(scan(10.025, 110.045)) == pytest.approx(110.045 - ready + front, abs=1e-6)
    assert c.scan_time(scan(10.050, 110.200)) == pytest.approx(110.070 - ready + front, abs=1e-5)
    # the sensor rebooted: its clock starts again
    assert c.scan_time(scan(0.0, 120.0)) == pytest.approx(120.0 - ready + front, abs=1e-6)


def test_with_the_backend_attached_a_drive_sent_over_mcp_moves_the_world_the_lidar_sees(
        ) -> None:
    world = MarteWorld.seeded(5)
    world.place(1.0, 1.0, 0.0)
    backend = SimBackend(world)
    with Rig(world, seed=5, backend=backend) as rig:
        assert rig.scheduler is backend.scheduler and rig.clock is backend.clock
        replies: list[object] = []
        link = McpLink(backend.address, clock=rig.clock, loop=rig.scheduler,
                       on_connect=lambda ln: ln.send("robot:control.acquire=(autonomy)",
                                                     replies.append))
        rig.scheduler.add_task("autonomy.mcp", rig.scheduler.rate_hz, link.tick)
        link.start()
        assert rig.run_until(lambda: rig.perception.ready and bool(replies), 5.0)
        x0 = world.x
        ahead0 = rig.lidar.latest.range_at(0.0)  # type: ignore[union-attr]
        link.send("base:base.drive=(50,0)", replies.append)
        rig.odometry.command(rig.clock.now(), 50, 0)
        rig.run_for(3.0)
        link.send("base:base.stop=()", replies.append)
        rig.odometry.stop(rig.clock.now())
        rig.run_for(1.0)
        moved = world.x - x0
        assert 0.3 < moved < 0.5  # 3 s at half of 0.3 m/s
        assert rig.odometry.pose[0] == pytest.approx(moved, abs=0.03)
        ahead1 = rig.lidar.latest.range_at(0.0)  # type: ignore[union-attr]
        assert ahead0 - ahead1 == pytest.approx(moved, abs=0.04)  # the far wall came closer
        assert rig.ahrs.settled and not rig.ahrs.suspect
        link.stop()
    assert backend.closed


def test_scans_on_demand_come_one_per_request() -> None:
    world = MarteWorld.seeded(4)
    with Rig(world, seed=4, stream=False) as rig:
        assert rig.run_until(lambda: rig.perception.ready, 5.0)
        assert rig.lidar.state == "ready"
        before = len(rig.scans.records)
        rig.run_for(0.5)
        assert len(rig.scans.records) == before  # nothing unasked for
        assert rig.lidar.request_scan()
        rig.run_for(0.1)
        assert len(rig.scans.records) == before + 1


@pytest.mark.parametrize(("loop_hz", "estimation_hz", "expected"), [
    (100.0, 50.0, 50.0), (100.0, 100.0, 100.0), (100.0, 20.0, 20.0),
    (200.0, 50.0, 50.0), (40.0, 50.0, 40.0), (60.0, 50.0, 30.0),
])
def test_state_estimation_runs_at_its_rate_and_what_a_sweep_waits_on_at_the_loops(
        loop_hz: float, estimation_hz: float, expected: float) -> None:
    """`estimation_hz` (autonomy.yaml) sets the rate of the IMU driver, odometry and the
    AHRS; on a loop it does not divide, the nearest slower rate that does (never faster than
    asked). The LIDAR driver, the scan collector and the gimbal run at the loop's rate."""
    cfg = replace(load_autonomy_config(), estimation_hz=estimation_hz)
    with Rig(MarteWorld.seeded(1), cfg, rate_hz=loop_hz) as rig:
        rates = {t.name: loop_hz / t.divisor for t in rig.scheduler.tasks
                 if t.name.startswith("autonomy.")}
        assert rates == {"autonomy.imu": expected, "autonomy.odometry": expected,
                         "autonomy.ahrs": expected, "autonomy.lidar": loop_hz,
                         "autonomy.scans": loop_hz, "autonomy.gimbal.servos": loop_hz,
                         "autonomy.gimbal.level": loop_hz}
        imu = next(t for t in rig.scheduler.tasks if t.name == "autonomy.imu")
        rig.run_for(1.0)
        assert imu.runs == pytest.approx(expected, abs=1)


def test_the_example_autonomy_yaml_estimates_at_50_hz() -> None:
    with Rig(MarteWorld.seeded(1)) as rig:
        halved = {t.name for t in rig.scheduler.tasks if t.divisor == 2}
        assert halved == {"autonomy.imu", "autonomy.odometry", "autonomy.ahrs"}
