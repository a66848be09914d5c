"""The wall-based localizer on scans of the simulated arena (SPEC 6.1, thesis 5.3.4).

Scans come from the simulator's ray-caster from the TRUE pose; the record carries what the
autonomy believes (`localizer_scenes.shoot`). Every result is also checked for the contract
the mission relies on: a pose is reported exactly when not lost, and then with a confidence
of at least HIGH_CONFIDENCE.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from firmware_like.arena import Layout, Rock
from firmware_like.lidar_view import LidarView
from firmware_like.marte import MarteWorld
from ramp.autonomy.perception.localizer import (
    HIGH_CONFIDENCE,
    Localization,
    Localizer,
    Pose,
    PosePrior,
    localize,
)
from ramp.autonomy.perception.records import ScanRecord
from tests.unit.localizer_scenes import errors, shoot

SEEDS = range(10)


def checked(res: Localization) -> Localization:
    """The result contract: pose None exactly when lost; a pose has high confidence; a
    loss says why; a pose comes with its covariance."""
    assert (res.pose is None) == res.lost
    assert 0.0 <= res.confidence <= 1.0
    if res.lost:
        assert res.confidence < HIGH_CONFIDENCE and res.reason
    else:
        assert res.confidence >= HIGH_CONFIDENCE and res.reason == ""
        assert res.covariance is not None and res.covariance.shape == (3, 3)
    return res


def sector(record: ScanRecord, lo_deg: float, hi_deg: float) -> ScanRecord:
    """Only the beams between two bearings, as a partial scan (first..last step) gives."""
    keep = (record.angles >= math.radians(lo_deg)) & (record.angles <= math.radians(hi_deg))
    return replace(record, ranges=record.ranges[keep], angles=record.angles[keep])


# ---- initial localization ------------------------------------------------------------------


@pytest.mark.parametrize("heading", [0, 90, 180, 270])
@pytest.mark.parametrize("box", ["left", "right"])
def test_every_start_box_and_heading_localizes_within_5cm_and_2deg(box: str,
                                                                    heading: int) -> None:
    for seed in SEEDS:
        world = MarteWorld.seeded(seed, box, heading)
        shot = shoot(world, LidarView.of(world))
        res = checked(localize(shot.record, hint=box))
        assert not res.lost, (seed, res.reason)
        dxy, dyaw = errors(res.pose, shot.truth)
        assert dxy < 0.05 and dyaw < 2.0, (seed, dxy, dyaw)
        # The scan alone allows the mirror pose: it is among the candidates (figure 5.39).
        twins = [c for c in res.candidates if abs(math.remainder(
            c.pose.yaw - shot.truth.yaw - math.pi, 2 * math.pi)) < math.radians(3)]
        assert twins and twins[0].probability < 0.01
        assert res.wall_points > 300 and res.residual_rms < 0.02


def test_random_poses_with_a_yaw_prior_within_30deg_are_accurate_or_lost() -> None:
    rng = np.random.default_rng(2014)
    lost = 0
    worst = (0.0, 0.0)
    for k in range(150):
        world = MarteWorld.seeded(k % 15)
        while True:
            x, y, yaw = rng.uniform(0, 7.38), rng.uniform(0, 3.88), rng.uniform(-180, 180)
            try:
                world.place(x, y, yaw)
                break
            except ValueError:
                continue
        prior = math.radians(yaw + rng.uniform(-30.0, 30.0))
        shot = shoot(world, LidarView.of(world))
        res = checked(localize(shot.record, yaw_prior=prior))
        if res.lost:
            lost += 1
            continue
        dxy, dyaw = errors(res.pose, shot.truth)
        # Never confident and wrong; when confident, within 10 cm and 3 degrees.
        assert not (dxy > 0.25 or dyaw > 10.0), (k, dxy, dyaw)
        assert dxy < 0.10 and dyaw < 3.0, (k, dxy, dyaw)
        worst = (max(worst[0], dxy), max(worst[1], dyaw))
    # Lost only where it must be (a wheel on a rock leans MARTE beyond what it trusts).
    assert lost <= 5, lost
    assert worst[0] < 0.02 and worst[1] < 0.5, worst


def test_without_any_prior_the_mirror_pose_leaves_it_lost() -> None:
    world = MarteWorld.seeded(3, "left", 0)
    shot = shoot(world, LidarView.of(world))
    res = checked(localize(shot.record))
    assert res.lost and "symmetric" in res.reason
    probs = sorted(c.probability for c in res.candidates)
    assert probs[-1] == pytest.approx(0.5, abs=0.05) and probs[-2] == pytest.approx(0.5,
                                                                                     abs=0.05)
    poses = [c.pose for c in res.candidates if c.probability > 0.4]
    truth = shot.truth
    mirror = Pose(7.38 - truth.x, 3.88 - truth.y, truth.yaw + math.pi)
    assert min(errors(p, truth)[0] for p in poses) < 0.05
    assert min(errors(p, mirror)[0] for p in poses) < 0.05


def test_a_yaw_prior_that_cannot_tell_the_twins_apart_is_lost_not_a_guess() -> None:
    world = MarteWorld.seeded(5, "right", 90)
    shot = shoot(world, LidarView.of(world))
    # 90 degrees off: the pose and its mirror are equally far from it.
    res = checked(localize(shot.record, yaw_prior=shot.truth.yaw + math.pi / 2))
    assert res.lost
    assert "yaw prior" in res.reason or "symmetric" in res.reason


def test_the_start_box_hint_alone_picks_the_true_pose() -> None:
    world = MarteWorld.seeded(8, "right", 180)
    shot = shoot(world, LidarView.of(world))
    res = checked(localize(shot.record, hint="right"))
    assert not res.lost and errors(res.pose, shot.truth)[0] < 0.05
    # A wrong box: the only pose inside it (a 90-degree alias) explains the scan far worse
    # than the true one outside it. Lost, not a confident pose in the wrong box.
    wrong = checked(localize(shot.record, hint="left"))
    assert wrong.lost and "priors rule out" in wrong.reason


def test_results_are_deterministic() -> None:
    world = MarteWorld.seeded(4, "left", 270)
    shot = shoot(world, LidarView.of(world))
    a = localize(shot.record, hint="left")
    b = localize(shot.record, hint="left")
    assert a.pose == b.pose and a.confidence == b.confidence
    assert [c.pose for c in a.candidates] == [c.pose for c in b.candidates]


# ---- what else a scan carries -----------------------------------------------------------------


def test_the_robots_frame_and_a_tall_rock_in_view_do_not_move_the_pose() -> None:
    # A boulder taller than the scan plane 1.2 m ahead: an arc of returns, not a wall.
    layout = Layout(rocks=(Rock(3.6, 1.94, 0.6, 0.9),))
    world = MarteWorld(seed=1, layout=layout)
    world.place(2.2, 1.94, 0.0)
    shot = shoot(world, LidarView.of(world))
    assert int((shot.scan.kinds == 3).sum()) > 40  # the rock is in the scan
    assert int((shot.scan.kinds == 5).sum()) > 40  # and so are the BLE's frame posts
    res = checked(localize(shot.record, yaw_prior=0.1))
    assert not res.lost
    dxy, dyaw = errors(res.pose, shot.truth)
    assert dxy < 0.03 and dyaw < 1.0
    assert all(s.length > 0.5 for s in res.segments)  # the arc made no segment


def test_a_scan_tilted_down_at_a_rock_localizes_from_the_walls_above_it() -> None:
    # A sweep of the 3D scan: the gimbal 10 degrees down sees the ground and a rock ahead;
    # with the attitude known they are below the walls' band and left out. The side walls
    # and the back wall (beside the BLE's posts, where the tipped plane rises) remain.
    layout = Layout(rocks=(Rock(4.2, 1.2, 0.3, 0.24),))
    world = MarteWorld(seed=2, layout=layout)
    world.place(1.0, 1.2, 0.0)
    shot = shoot(world, LidarView.of(world), tilt=-world.pitch + math.radians(10.0))
    kinds = shot.scan.kinds
    assert int((kinds == 2).sum()) > 50 and int((kinds == 3).sum()) > 5  # ground, rock
    res = checked(localize(shot.record, hint="right"))
    assert not res.lost, res.reason
    dxy, dyaw = errors(res.pose, shot.truth)
    assert dxy < 0.05 and dyaw < 2.0


def test_dust_while_digging_does_not_disturb_the_fix() -> None:
    world = MarteWorld.seeded(6)
    world.place(5.5, 1.5, 10.0)
    shot = shoot(world, LidarView.of(world), digging=True)
    assert int((shot.scan.kinds == 6).sum()) >= 5
    res = checked(localize(shot.record, yaw_prior=0.0))
    assert not res.lost
    assert errors(res.pose, shot.truth)[0] < 0.03


def test_one_wall_in_view_is_lost_alone_and_tracked_with_odometry() -> None:
    world = MarteWorld.seeded(7)
    world.place(3.0, 1.94, 0.0)
    shot = shoot(world, LidarView.of(world))
    record = sector(shot.record, -20.0, 20.0)  # only the far wall, 4 m ahead
    alone = checked(localize(record, yaw_prior=0.0))
    assert alone.lost and "unobservable" in alone.reason
    truth = shot.truth
    prior = PosePrior(Pose(truth.x + 0.03, truth.y - 0.04, truth.yaw + 0.01),
                      np.diag((0.05 ** 2, 0.05 ** 2, math.radians(2) ** 2)))
    res = checked(localize(record, yaw_prior=0.0, prior=prior))
    assert not res.lost, res.reason
    assert abs(res.pose.x - truth.x) < 0.02  # the wall fixes x and the yaw ...
    assert abs(math.degrees(res.pose.yaw - truth.yaw)) < 0.5
    assert abs(res.pose.y - prior.pose.y) < 0.01  # ... y is the odometry's, as uncertain
    assert math.sqrt(res.covariance[1, 1]) > 0.04


def test_disagreeing_with_odometry_is_lost() -> None:
    world = MarteWorld.seeded(9)
    world.place(4.0, 2.0, 30.0)
    shot = shoot(world, LidarView.of(world))
    t = shot.truth
    prior = PosePrior(Pose(t.x + 0.5, t.y, t.yaw), np.diag((0.05 ** 2, 0.05 ** 2, 0.02 ** 2)))
    res = checked(localize(shot.record, yaw_prior=t.yaw, prior=prior))
    assert res.lost and "odometry" in res.reason
    assert res.best is not None and errors(res.best.pose, t)[0] < 0.05  # still plotted


def test_too_few_returns_are_lost() -> None:
    world = MarteWorld.seeded(1)
    shot = shoot(world, LidarView.of(world))
    res = checked(localize(sector(shot.record, -1.0, 1.0), yaw_prior=shot.truth.yaw))
    assert res.lost and "too few" in res.reason


# ---- tracking between scans -----------------------------------------------------------------


def drive(world: MarteWorld, forward: float, turn_deg: float) -> tuple[float, float, float]:
    """Teleport the robot along an arc and return the robot-frame motion (dx, dy, dyaw)."""
    x0, y0, h0 = world.x, world.y, world.yaw
    h1 = h0 + math.radians(turn_deg)
    mid = h0 + math.radians(turn_deg) / 2
    world.place(x0 + forward * math.cos(mid), y0 + forward * math.sin(mid), math.degrees(h1))
    c, s = math.cos(h0), math.sin(h0)
    dx, dy = world.x - x0, world.y - y0
    return c * dx + s * dy, -s * dx + c * dy, math.remainder(world.yaw - h0, 2 * math.pi)


def test_tracking_with_odometry_then_a_kidnap_is_noticed_and_relocalized() -> None:
    rng = np.random.default_rng(5)
    world = MarteWorld.seeded(12, "left", 0)
    view = LidarView.of(world)
    loc = Localizer()
    shot = shoot(world, view, yaw=world.yaw + math.radians(12))
    first = checked(loc.initialise(shot.record, hint="left"))
    assert not first.lost and not loc.lost
    for forward, turn in [(0.4, -20), (0.5, -15), (0.5, 0), (0.5, 10), (0.4, 5), (0.5, 0)]:
        dx, dy, dyaw = drive(world, forward, turn)
        # Odometry from the commands: a few percent off, as skid steering is.
        loc.predict(dx * 1.04, dy + 0.01, dyaw * 0.95)
        shot = shoot(world, view, yaw=world.yaw + math.radians(rng.uniform(-15, 15)))
        res = checked(loc.update(shot.record))
        assert not res.lost, res.reason
        dxy, dyaw_err = errors(res.pose, shot.truth)
        assert dxy < 0.05 and dyaw_err < 2.0
        assert loc.pose == res.pose
    # Kidnapped: carried 1.2 m sideways with no odometry. The scan disagrees: lost.
    world.place(world.x, world.y - 1.2 if world.y > 1.94 else world.y + 1.2,
                math.degrees(world.yaw))
    shot = shoot(world, view, yaw=world.yaw)
    res = checked(loc.update(shot.record))
    assert res.lost and "odometry" in res.reason and loc.lost
    # The recovery the mission runs: re-localize without the pose prior.
    res = checked(loc.relocalize(shot.record))
    assert not res.lost and errors(res.pose, shot.truth)[0] < 0.05 and not loc.lost


def test_prediction_grows_the_covariance_with_the_motion() -> None:
    world = MarteWorld.seeded(3, "right", 90)
    loc = Localizer()
    loc.initialise(shoot(world, LidarView.of(world)).record, hint="right")
    before = loc.covariance
    pose = loc.pose
    assert before is not None and pose is not None
    loc.predict(1.0, 0.0, math.radians(30))
    after = loc.covariance
    assert after is not None and loc.pose is not None
    assert np.trace(after) > np.trace(before)
    assert math.hypot(loc.pose.x - pose.x, loc.pose.y - pose.y) == pytest.approx(1.0)
    assert math.remainder(loc.pose.yaw - pose.yaw - math.radians(30), 2 * math.pi) == (
        pytest.approx(0.0, abs=1e-12))
