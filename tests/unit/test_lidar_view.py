"""The LIDAR's view of the arena: ray-cast ranges against hand-computed geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_like.arena import Crater, Layout, Rock
from firmware_like.arena_params import (
    HIT_CRATER,
    HIT_DUST,
    HIT_FRAME,
    HIT_GROUND,
    HIT_NONE,
    HIT_ROCK,
    HIT_WALL,
    ArenaParams,
    LidarParams,
)
from firmware_like.lidar_view import LidarView, rotation_zyx
from firmware_like.marte import MarteWorld
from firmware_like.terrain import Terrain

FLAT = ArenaParams(ground_amplitude=0.0)
FRONT = 540
MOUNT_X, MOUNT_Z = 0.40, 0.70  # LidarParams defaults: the scanner's place on the chassis


def step(angle_deg: float) -> int:
    """The step whose beam points at this angle (0.25 deg per step, CCW positive)."""
    return FRONT + round(angle_deg * 4)


def view(rocks: tuple[Rock, ...] = (), craters: tuple[Crater, ...] = (),
         params: LidarParams | None = None, arena: ArenaParams = FLAT,
         seed: int = 0) -> LidarView:
    layout = Layout(rocks, craters)
    return LidarView(Terrain(layout, arena, seed), arena=arena, params=params, seed=seed)


def exact(v: LidarView, x: float, y: float, yaw_deg: float, tilt_deg: float = 0.0,
          pan_deg: float = 0.0, pitch_deg: float = 0.0, roll_deg: float = 0.0):  # noqa: ANN201
    pose = v.pose(x, y, 0.0, math.radians(roll_deg), math.radians(pitch_deg),
                  math.radians(yaw_deg), math.radians(pan_deg), math.radians(tilt_deg))
    return v.scan(pose, noise=False)


# ---- walls ---------------------------------------------------------------------------------


def test_level_scan_sees_the_walls_at_hand_computed_ranges() -> None:
    v = view()
    s = exact(v, 3.0, 1.94, 0.0)  # scanner at (3.40, 1.94, 0.70)
    assert s.kinds[FRONT] == HIT_WALL
    assert s.ranges[FRONT] == pytest.approx(7.38 - 3.40, abs=1e-9)  # far wall, ahead
    assert s.ranges[step(90)] == pytest.approx(3.88 - 1.94, abs=1e-9)  # left wall (+y)
    assert s.ranges[step(-90)] == pytest.approx(1.94, abs=1e-9)  # right wall (y = 0)
    # 30 deg left: the far wall is 3.98 / cos 30 = 4.596 away, the left wall 1.94 / sin 30 =
    # 3.88: the left wall is hit first.
    assert s.ranges[step(30)] == pytest.approx(3.88, abs=1e-9)
    # 20 deg right: far wall 3.98 / cos 20 = 4.2355, right wall 1.94 / sin 20 = 5.672.
    assert s.ranges[step(-20)] == pytest.approx(3.98 / math.cos(math.radians(20)), abs=1e-9)
    assert s.mm[FRONT] == 3980
    assert (s.kinds[:5] == HIT_WALL).all()  # the -135 deg edge of the field of view


def test_yaw_is_counter_clockwise_and_beams_turn_with_the_robot() -> None:
    v = view()
    s = exact(v, 3.0, 1.94, 90.0)  # facing +y: scanner at (3.00, 2.34)
    assert s.ranges[FRONT] == pytest.approx(3.88 - 2.34, abs=1e-9)
    assert s.ranges[step(90)] == pytest.approx(3.0, abs=1e-9)  # its left is -x: x = 0 wall
    assert s.ranges[step(-90)] == pytest.approx(7.38 - 3.0, abs=1e-9)


def test_pan_turns_the_scan_counter_clockwise() -> None:
    v = view()
    s = exact(v, 3.0, 1.94, 0.0, pan_deg=90.0)
    assert s.ranges[FRONT] == pytest.approx(3.88 - 1.94, abs=1e-9)


def test_a_beam_over_the_wall_gets_no_echo_and_reads_an_error_code() -> None:
    v = view()
    s = exact(v, 3.0, 1.94, 0.0, tilt_deg=-30.0)  # tilted up 30 deg
    # Ahead the wall is 3.98 m away: the beam is 0.70 + 3.98 tan 30 = 3.0 m up there.
    assert s.kinds[FRONT] == HIT_NONE
    assert np.isnan(s.ranges[FRONT])
    assert s.mm[FRONT] == LidarParams().no_return_mm < 23
    # Sideways the tilt does not lift the beam: it still meets the side walls.
    assert s.kinds[step(90)] == HIT_WALL


# ---- ground -------------------------------------------------------------------------------


@pytest.mark.parametrize("tilt", [10.0, 20.0, 35.0])
def test_a_tilted_beam_meets_flat_ground_at_height_over_sin_tilt(tilt: float) -> None:
    v = view()
    s = exact(v, 3.0, 1.94, 0.0, tilt_deg=tilt)
    sin_t = math.sin(math.radians(tilt))
    assert s.kinds[FRONT] == HIT_GROUND
    assert s.ranges[FRONT] == pytest.approx(MOUNT_Z / sin_t, abs=1e-6)
    # A beam at azimuth a drops by cos(a) sin(tilt) per metre.
    a = math.radians(30.0)
    if MOUNT_Z / (math.cos(a) * sin_t) < 1.94 / math.sin(a):  # the ground before the wall
        assert s.ranges[step(30)] == pytest.approx(MOUNT_Z / (math.cos(a) * sin_t), abs=1e-6)


def test_a_pitched_chassis_tilts_the_scan_like_the_gimbal_with_the_mount_lowered() -> None:
    v = view()
    s = exact(v, 3.0, 1.94, 0.0, pitch_deg=20.0)  # nose down 20 deg, gimbal level
    # The scanner is 0.40 m ahead of the centre and 0.70 m up: pitched, it sits at
    # z = 0.70 cos 20 - 0.40 sin 20 = 0.5210 m and looks 20 deg down.
    z = MOUNT_Z * math.cos(math.radians(20)) - MOUNT_X * math.sin(math.radians(20))
    assert s.pose.origin[2] == pytest.approx(z, abs=1e-9)
    assert s.ranges[FRONT] == pytest.approx(z / math.sin(math.radians(20)), abs=1e-6)
    # Rolled 15 deg left side up, near the left wall: the scanner sits at 0.70 cos 15 and the
    # beam to the right goes down 15 deg, meeting the ground 0.676 / sin 15 = 2.61 m away,
    # before the right wall (3.2 m).
    rolled = exact(v, 3.0, 3.2, 0.0, roll_deg=15.0)
    assert rolled.kinds[step(-90)] == HIT_GROUND
    assert rolled.ranges[step(-90)] == pytest.approx(
        MOUNT_Z * math.cos(math.radians(15)) / math.sin(math.radians(15)), abs=1e-6)
    assert rolled.kinds[step(90)] == HIT_WALL


def test_ground_hits_lie_on_the_undulating_ground() -> None:
    arena = ArenaParams(ground_amplitude=0.03)
    v = view(arena=arena, seed=5)
    for tilt in (12.0, 18.0, 25.0):
        s = exact(v, 2.0, 1.5, 30.0, tilt_deg=tilt)
        ground = s.kinds == HIT_GROUND
        assert ground.sum() > 50
        p = s.points()[ground]
        assert np.abs(p[:, 2] - v.terrain.ground(p[:, 0], p[:, 1])).max() < 1e-3


@pytest.mark.parametrize("amplitude", [0.03, 0.15])
def test_ground_hit_is_the_first_crossing_found_by_fine_marching(amplitude: float) -> None:
    # 0.15 m waves are rougher than any arena: slopes up to ~20 deg, so shallow beams take the
    # sampled path (a crest can come before the crossing the flat estimate points at).
    v = view(arena=ArenaParams(ground_amplitude=amplitude), seed=11)
    s = exact(v, 1.0, 0.6, 20.0, tilt_deg=9.0)
    ground = np.nonzero(s.kinds == HIT_GROUND)[0]
    assert ground.size > 100
    dirs, origin = s.dirs, s.pose.origin
    for k in ground[::10]:
        ts = np.arange(0.0, s.ranges[k] + 0.05, 0.001)
        p = origin + ts[:, None] * dirs[k]
        above = p[:, 2] - v.terrain.ground(p[:, 0], p[:, 1])
        first = ts[np.argmax(above <= 0.0)]
        assert s.ranges[k] == pytest.approx(first, abs=0.002)


# ---- rocks and craters -----------------------------------------------------------------------


def test_a_rock_straight_ahead_is_hit_at_the_dome_s_near_side() -> None:
    # A tall rock (0.9 m dome) 1.25 m ahead of the scanner: the level beam at z = 0.70 meets
    # the half-ellipsoid where its radius is 0.15 sqrt(1 - (0.7 / 0.9)^2) = 0.09428 m.
    rock = Rock(4.65, 1.94, 0.30, 0.90)
    s = exact(view((rock,)), 3.0, 1.94, 0.0)
    radius_at_beam = 0.15 * math.sqrt(1.0 - (0.70 / 0.90) ** 2)
    assert s.kinds[FRONT] == HIT_ROCK
    assert s.ranges[FRONT] == pytest.approx(4.65 - radius_at_beam - 3.40, abs=1e-9)
    # 0.3 m wide at 1.25 m: about 12 deg of beams, not the ones 10 deg to each side.
    assert s.kinds[step(10)] == HIT_WALL and s.kinds[step(-10)] == HIT_WALL


def test_a_low_rock_shows_above_the_ground_in_a_tilted_scan() -> None:
    rock = Rock(5.20, 1.94, 0.30, 0.18)  # where the 20 deg beam would meet the ground
    v = view((rock,))
    bare = exact(view(), 3.0, 1.94, 0.0, tilt_deg=20.0)
    s = exact(v, 3.0, 1.94, 0.0, tilt_deg=20.0)
    hits = np.nonzero(s.kinds == HIT_ROCK)[0]
    assert FRONT in hits and 5 < hits.size < 60
    assert (s.ranges[hits] < bare.ranges[hits]).all()  # the rock is in front of the ground
    p = s.points()[hits]
    assert (p[:, 2] > 0.0).all()
    on_dome = ((p[:, 0] - 5.20) ** 2 + (p[:, 1] - 1.94) ** 2) / 0.15 ** 2 + (p[:, 2] / 0.18) ** 2
    assert np.allclose(on_dome, 1.0, atol=1e-9)


def test_a_crater_is_a_gap_of_longer_ranges_below_the_ground_in_a_tilted_scan() -> None:
    tilt = math.radians(20.0)
    ground_x = 3.40 + MOUNT_Z / math.tan(tilt)  # where the front beam meets flat ground
    crater = Crater(ground_x, 1.94, 0.30, 0.25)
    bare = exact(view(), 3.0, 1.94, 0.0, tilt_deg=20.0)
    s = exact(view(craters=(crater,)), 3.0, 1.94, 0.0, tilt_deg=20.0)
    # By hand: the beam z = 0.7 - t sin(20), x = 3.4 + t cos(20) meets the bowl
    # z = -0.25 (1 - r^2 / 0.15^2) on the far side; solve the quadratic in t.
    k = 0.25 / 0.15 ** 2
    ex = 3.40 - ground_x
    a = k * math.cos(tilt) ** 2
    b = 2 * k * ex * math.cos(tilt) + math.sin(tilt)
    c = k * ex * ex - 0.25 - 0.70
    far = (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)
    assert s.kinds[FRONT] == HIT_CRATER
    assert s.ranges[FRONT] == pytest.approx(far, abs=1e-9)
    assert s.ranges[FRONT] > bare.ranges[FRONT] + 0.05
    gap = np.nonzero(s.kinds == HIT_CRATER)[0]
    assert 5 < gap.size < 40
    assert (s.ranges[gap] > bare.ranges[gap]).all()
    assert (s.points()[gap, 2] < 0.0).all()  # seen below the ground
    others = np.setdiff1d(np.arange(1081), gap)
    assert np.array_equal(s.ranges[others], bare.ranges[others], equal_nan=True)


# ---- the robot's own frame -----------------------------------------------------------------


def test_the_robot_s_frame_is_seen_at_a_fixed_short_range() -> None:
    v = view()
    s = exact(v, 3.0, 1.94, 0.0)
    frame = np.nonzero(s.kinds == HIT_FRAME)[0]
    assert 10 < frame.size < 100  # a few beams, as in thesis figure 5.38
    # The left post's inner face y = 0.31, 0.40 - 0.17 = 0.23 m to 0.27 m behind the scanner
    # and 0.70 m up the 0.20-0.95 m post: the beam at 127 deg meets it at 0.31 / sin 127.
    k = step(127)
    assert s.kinds[k] == HIT_FRAME
    assert s.ranges[k] == pytest.approx(0.31 / math.sin(math.radians(127)), abs=1e-9)
    assert (s.ranges[frame] < 0.5).all()
    elsewhere = exact(v, 5.5, 0.9, 140.0, pitch_deg=3.0)  # same steps, any pose
    assert np.array_equal(np.nonzero(elsewhere.kinds == HIT_FRAME)[0], frame)
    assert np.allclose(elsewhere.ranges[frame], s.ranges[frame])


# ---- the sensor: noise, dust, SCIP values ---------------------------------------------------


def test_range_noise_is_seeded_and_has_the_datasheet_spread() -> None:
    a, b, c = view(seed=1), view(seed=1), view(seed=2)
    truth = exact(a, 3.0, 1.94, 0.0)
    pose = truth.pose
    sa, sb, sc = a.scan(pose), b.scan(pose), c.scan(pose)
    assert np.array_equal(sa.mm, sb.mm)
    assert not np.array_equal(sa.mm, sc.mm)
    walls = (sa.kinds == HIT_WALL) & (truth.kinds == HIT_WALL)
    err = sa.ranges[walls] - truth.ranges[walls]
    assert 0.007 < err.std() < 0.013  # sigma 10 mm
    assert abs(err.mean()) < 0.002


def test_dust_returns_short_of_the_target() -> None:
    v = view(params=LidarParams(dust_probability=0.5))
    truth = exact(v, 3.0, 1.94, 0.0)
    s = v.scan(truth.pose)
    dust = s.kinds == HIT_DUST
    assert 300 < dust.sum() < 700
    assert (s.ranges[dust] < truth.ranges[dust]).all()
    assert (s.ranges[dust] >= 0.15).all() and (s.ranges[dust] <= 1.5).all()
    calm = view().scan(truth.pose)
    assert (calm.kinds == HIT_DUST).sum() < 15


def test_values_are_int_millimetres_with_error_codes_below_dmin() -> None:
    v = view()
    s = v.scan(exact(v, 3.0, 1.94, 0.0, tilt_deg=-30.0).pose)
    assert s.mm.dtype == np.int64 and s.mm.shape == (1081,)
    echo = s.kinds != HIT_NONE
    assert (s.mm[echo] >= 100).all() and (s.mm[echo] <= 30000).all()
    assert (s.mm[~echo] < 23).all() and (~echo).sum() > 100
    assert np.array_equal(s.mm[echo], np.rint(s.ranges[echo] * 1000).astype(np.int64))


def test_range_source_scans_the_live_world_from_its_chassis_and_gimbal() -> None:
    world = MarteWorld.seeded(4)
    world.place(3.0, 1.94, 0.0)
    gimbal = [0.0, 0.0]
    v = LidarView.of(world, gimbal=lambda: (gimbal[0], gimbal[1]))
    level = v.range_source(0.0)
    assert level.shape == (1081,) and level.dtype == np.int64
    assert abs(level[FRONT] - 3980) < 60  # the far wall, noise and the ground's tilt aside
    gimbal[1] = math.radians(20.0)
    tilted = v.range_source(0.025)
    assert tilted[FRONT] < level[FRONT] - 1000  # now the ground, ~2 m ahead
    world.place(5.0, 1.94, 0.0)
    gimbal[1] = 0.0
    assert abs(v.range_source(0.05)[FRONT] - 1980) < 60


def test_rotation_is_z_y_x_with_pitch_nose_down() -> None:
    r = rotation_zyx(math.radians(90), 0.0, 0.0)
    assert np.allclose(r @ [1, 0, 0], [0, 1, 0])  # yaw 90: forward is +y
    r = rotation_zyx(0.0, math.radians(30), 0.0)
    assert r @ np.array([1.0, 0.0, 0.0]) == pytest.approx([math.cos(0.5236), 0, -0.5], abs=1e-4)
    r = rotation_zyx(0.0, 0.0, math.radians(30))
    assert (r @ np.array([0.0, 1.0, 0.0]))[2] > 0  # roll positive: the left side up


def test_seeded_arenas_agree_with_marching_each_beam_through_the_height_field() -> None:
    """The fast ray-caster (pruned by angle, closed-form rocks and bowls, bracketed ground)
    against the slow truth: step along the beam 1 mm at a time until it is under the
    surface (ground, rock domes and crater bowls together)."""
    kinds_seen: set[int] = set()
    for seed in range(6):
        world = MarteWorld.seeded(seed)
        world.place(1.0, 1.0 + (seed % 4) * 0.6, (seed * 7) % 40 - 20)
        v = LidarView.of(world)
        for tilt in (15.0, 30.0):
            s = v.scan(v.pose_of_world(0.0, math.radians(tilt)), noise=False)
            terrain = np.isin(s.kinds, (HIT_GROUND, HIT_ROCK, HIT_CRATER))
            picked = np.nonzero(terrain & ((np.arange(1081) % 8 == 0) | (s.kinds != HIT_GROUND)))
            for k in picked[0]:
                kinds_seen.add(int(s.kinds[k]))
                ts = np.arange(0.0, s.ranges[k] + 0.02, 0.001)
                p = s.pose.origin + ts[:, None] * s.dirs[k]
                under = p[:, 2] <= world.terrain.height(p[:, 0], p[:, 1])
                assert under.any()
                assert s.ranges[k] == pytest.approx(ts[np.argmax(under)], abs=0.002), (seed, k)
    assert kinds_seen == {HIT_GROUND, HIT_ROCK, HIT_CRATER}
