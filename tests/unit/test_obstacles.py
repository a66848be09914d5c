"""Obstacle detection (issue 15, SPEC 6.1): its pieces on made-up data, then the whole of it
on 3D scans of simulated arenas (`tests/obstacle_scenes.py`: the LIDAR ray-caster with its
noise, dust and the robot's own frame, the AHRS' attitude a little off).

The bar: on at least 40 seeded layouts scanned from the start region, every rock and crater
of 15 cm or more found within 10 cm of its true position with its diameter within 5 cm, at
most 0.5 false obstacles per layout on average, rocks and craters never confused."""

from __future__ import annotations

import math
import random
from dataclasses import replace

import numpy as np
import pytest

from firmware_like.arena import Crater, Layout, Rock, StartSpec, disc_overlap
from firmware_like.marte import MarteWorld
from firmware_like.world_file import load_world
from ramp.autonomy.perception.cloud import Cloud
from ramp.autonomy.perception.obstacles import (
    CRATER,
    GROUND,
    IGNORED,
    ROCK,
    Detection,
    DetectionParams,
    Obstacle,
    _bowl_fit,
    _dome_fit,
    clusters,
    detect_obstacles,
    fit_ground,
    fit_plane_ransac,
    kept_points,
    level_scans,
    wall_offsets,
)
from tests.obstacle_scenes import Match, Scene, match, scan_world, sweep_plan

LAYOUTS = 40
POSITION_BOUND = 0.10
DIAMETER_BOUND = 0.05


# ---- pieces ----------------------------------------------------------------------------


def test_ransac_finds_the_ground_plane_under_rocks_and_walls() -> None:
    rng = np.random.default_rng(1)
    xy = rng.uniform(0.0, 3.0, (3000, 2))
    ground = np.column_stack((xy, 0.02 * xy[:, 0] - 0.01 * xy[:, 1] + 0.05
                              + rng.normal(0.0, 0.005, 3000)))
    junk = np.column_stack((rng.uniform(0, 3, (1500, 2)), rng.uniform(0.05, 0.6, 1500)))
    a, b, c = fit_plane_ransac(np.concatenate((ground, junk)))
    assert (a, b, c) == pytest.approx((0.02, -0.01, 0.05), abs=2e-3)
    # deterministic: the same answer again
    assert fit_plane_ransac(np.concatenate((ground, junk))) == (a, b, c)


def test_the_ground_model_follows_the_rakes_undulation_and_ignores_a_rock() -> None:
    rng = np.random.default_rng(2)
    xy = rng.uniform((1.0, 0.0), (4.5, 3.88), (40000, 2))

    def wave(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return 0.012 * np.sin(2 * np.pi * x / 1.6 + 0.3) + 0.008 * np.sin(2 * np.pi * y / 2.2)

    z = wave(xy[:, 0], xy[:, 1]) + rng.normal(0.0, 0.004, xy.shape[0])
    rho = np.hypot(xy[:, 0] - 2.5, xy[:, 1] - 2.0)
    rock = rho < 0.15
    z[rock] += 0.18 * np.sqrt(1.0 - (rho[rock] / 0.15) ** 2)
    model = fit_ground(np.column_stack((xy, z)))
    gx, gy = np.meshgrid(np.linspace(1.3, 4.2, 30), np.linspace(0.3, 3.6, 30))
    err = model.height(gx, gy) - wave(gx, gy)
    assert np.abs(err).max() < 0.006
    assert abs(model.at(2.5, 2.0) - float(wave(np.array(2.5), np.array(2.0)))) < 0.006


def test_single_linkage_joins_chains_and_splits_groups_farther_than_the_link() -> None:
    line = np.column_stack((np.arange(50) * 0.04, np.zeros(50)))  # 4 cm steps: one chain
    assert [len(g) for g in clusters(line, 0.05)] == [50]
    rng = np.random.default_rng(3)
    a = rng.normal((0.0, 0.0), 0.02, (40, 2))
    b = rng.normal((0.4, 0.0), 0.02, (30, 2))
    groups = clusters(np.concatenate((a, b, [[5.0, 5.0]])), 0.05)
    assert sorted(len(g) for g in groups) == [1, 30, 40]
    assert clusters(np.zeros((0, 2)), 0.05) == []


def test_a_dome_and_a_bowl_are_recovered_exactly_from_points_on_them() -> None:
    rng = np.random.default_rng(4)
    ang, rho = rng.uniform(0, 2 * np.pi, 200), rng.uniform(0.0, 0.95, 200)
    x, y = 2.0 + 0.12 * rho * np.cos(ang), 1.0 + 0.12 * rho * np.sin(ang)
    dome = _dome_fit(x, y, 0.09 * np.sqrt(1.0 - rho ** 2))
    assert dome == pytest.approx((2.0, 1.0, 0.12, 0.09), abs=1e-9)
    rim = np.column_stack((2.0 + 0.1 * np.cos(ang[:12]), 1.0 + 0.1 * np.sin(ang[:12]),
                           np.zeros(12)))
    wall = np.column_stack((x, y, -0.2 * (1.0 - (0.12 * rho / 0.1) ** 2)))[rho < 0.8]
    bowl = _bowl_fit(rim, wall)
    assert bowl == pytest.approx((2.0, 1.0, 0.1, 0.2), abs=1e-9)


def _flat_scene(seed: int) -> Scene:
    world = MarteWorld(layout=Layout(start=StartSpec("left", 0.0)), seed=seed)
    return scan_world(world, 0.9, 1.94, 0.0, seed=seed, wobble_deg=0.0,
                      attitude_error_deg=(0.0, 0.0))


def test_levelling_takes_out_a_tilt_error_of_one_scan() -> None:
    scene = _flat_scene(5)
    cloud = scene.cloud
    p = DetectionParams()
    keep = kept_points(cloud, p)
    ground = fit_ground(cloud.points[keep], p)
    # scan 3 (far, ~3.6 m ahead) turned 0.3 deg nose down about its scanner
    bad = cloud.scan == 3
    rel = cloud.points[bad] - cloud.origins[3]
    tilted = cloud.points.copy()
    tilted[bad, 2] -= math.radians(0.3) * rel[:, 0]
    off = replace(cloud, points=tilted)
    h_before = tilted[bad, 2] - ground.height(tilted[bad, 0], tilted[bad, 1])
    levelled = level_scans(off, ground, keep, p.ground_band_m)
    fixed = levelled.points[bad]
    h_after = fixed[:, 2] - ground.height(fixed[:, 0], fixed[:, 1])
    on_ground = keep[bad]
    assert np.median(h_before[on_ground]) < -0.015
    assert abs(np.median(h_after[on_ground])) < 0.002


def test_the_robots_own_frame_and_the_walls_are_ignored() -> None:
    scene = _flat_scene(6)
    det = detect_obstacles(scene.cloud)
    assert det.obstacles == []
    p = scene.cloud.points
    own = (np.abs(p[:, 0] - 0.9) < 0.6) & (np.abs(p[:, 1] - 1.94) < 0.375)
    assert own.sum() > 100  # the BLE's posts are in the scans
    assert np.all(det.labels[own] == IGNORED)
    walls = (p[:, 1] < 0.02) | (p[:, 1] > 3.86)
    assert walls.sum() > 1000 and np.all(det.labels[walls] == IGNORED)


def test_dust_from_digging_makes_no_obstacle() -> None:
    world = MarteWorld(layout=Layout(start=StartSpec("left", 0.0)), seed=7)
    scene = scan_world(world, 0.9, 1.94, 0.0, seed=7, digging=True)  # 1 % of beams
    assert (scene.kinds == 6).sum() > 500  # HIT_DUST
    assert detect_obstacles(scene.cloud).obstacles == []


def test_an_empty_cloud_has_no_obstacles() -> None:
    empty = Cloud(np.zeros((0, 3)), np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp),
                  np.zeros((0, 3)), np.zeros(0), (1.0, 1.0, 0.0))
    det = detect_obstacles(empty)
    assert det.obstacles == [] and det.labels.shape == (0,)


def test_obstacles_serialise_as_the_perceive_commands_json_fields() -> None:
    o = Obstacle("crater", 2.34567, 1.0, 0.25049, height=0.2, points=40)
    assert o.as_dict() == {"kind": "crater", "x": 2.346, "y": 1.0, "d": 0.25}


# ---- the bar: 40 seeded layouts from the start region ----------------------------------


def start_pose(seed: int) -> tuple[float, float, float]:
    """Where "Prepare for Scan" leaves the robot: at the start region's front edge (the
    footprint wholly inside it), near the middle, facing the obstacles within a few
    degrees."""
    rng = random.Random(f"scan-pose:{seed}")
    return 0.80 + 0.10 * rng.random(), 1.94 + rng.uniform(-0.15, 0.15), rng.uniform(-3.0, 3.0)


@pytest.fixture(scope="module")
def start_region() -> list[tuple[Scene, Detection, list[Match], list[Obstacle]]]:
    out = []
    for seed in range(LAYOUTS):
        x, y, yaw = start_pose(seed)
        scene = scan_world(MarteWorld.seeded(seed), x, y, yaw, seed=seed)
        det = detect_obstacles(scene.cloud)
        matches, false = match(scene, det.obstacles)
        out.append((scene, det, matches, false))
    return out


def test_every_obstacle_of_15_cm_or_more_is_found_and_measured(start_region: list) -> None:
    checked = 0
    for scene, _, matches, _ in start_region:
        for m in matches:
            if m.truth["d"] < 0.15:
                continue
            checked += 1
            where = f"{scene.world.layout.source}: {m.kind} {m.truth}"
            assert m.found is not None, f"{where} missed ({m.seen} returns from it)"
            assert m.position_error <= POSITION_BOUND, f"{where} found at {m.found}"
            assert abs(m.diameter_error) <= DIAMETER_BOUND, f"{where} found as {m.found}"
    assert checked >= 4 * LAYOUTS  # nearly all of the five per layout are 15 cm or more


def test_the_measurements_are_far_inside_the_bounds(start_region: list) -> None:
    """The margin the bounds leave: worst position 2.5 cm, worst diameter 4 cm, and no bias
    worth the name (these 40 layouts: 1.4 cm, -2.1..+1.6 cm, mean -0.3 cm)."""
    found = [m for _, _, matches, _ in start_region for m in matches
             if m.found is not None and m.truth["d"] >= 0.15]
    assert max(m.position_error for m in found) < 0.025
    assert max(abs(m.diameter_error) for m in found) < 0.04
    assert abs(float(np.mean([m.diameter_error for m in found]))) < 0.01


def test_false_obstacles_are_rare(start_region: list) -> None:
    false = [q for *_, left in start_region for q in left]
    assert len(false) / LAYOUTS <= 0.5, false
    assert len(false) <= 2, false  # in fact none, these 40 layouts


def test_rocks_and_craters_are_never_confused(start_region: list) -> None:
    for scene, _, matches, _ in start_region:
        for m in matches:
            if m.found is not None:
                assert m.found.kind == m.kind, (scene.world.layout.source, m.truth, m.found)


def test_smaller_rocks_when_found_are_measured_as_well(start_region: list) -> None:
    small = [m for _, _, matches, _ in start_region for m in matches
             if m.truth["d"] < 0.15 and m.found is not None]
    assert small  # 10-15 cm rocks are mostly found too
    for m in small:
        assert m.position_error <= POSITION_BOUND and abs(m.diameter_error) <= DIAMETER_BOUND


def test_an_obstacle_half_hidden_behind_a_rock_is_flagged_partial(start_region: list) -> None:
    """Seed 267: the 17 cm crater at (4.14, 1.25) lies half in the shadow of a 26 cm rock
    0.6 m nearer the scanner. It is found, from its visible part (too small by 5 cm), and
    says so; the rock in front is whole. Of the 40 layouts above, few have any."""
    x, y, yaw = start_pose(267)
    scene = scan_world(MarteWorld.seeded(267), x, y, yaw, seed=267)
    matches, _ = match(scene, detect_obstacles(scene.cloud).obstacles)
    by_place = {(m.kind, round(m.truth["x"], 2)): m.found for m in matches}
    hidden, rock = by_place[("crater", 4.14)], by_place[("rock", 3.51)]
    assert hidden is not None and hidden.partial and hidden.d < 0.174
    assert rock is not None and not rock.partial
    flagged = [q for _, det, _, _ in start_region for q in det.obstacles if q.partial]
    assert len(flagged) <= 3


def test_the_labels_say_what_each_point_was_taken_for(start_region: list) -> None:
    scene, det, matches, _ = start_region[0]
    for m in matches:
        if m.found is None:
            continue
        p = det.cloud.points
        near = np.hypot(p[:, 0] - m.found.x, p[:, 1] - m.found.y) < m.found.d / 2
        want = ROCK if m.kind == "rock" else CRATER
        assert (det.labels[near] == want).sum() >= 6
    assert (det.labels == GROUND).sum() > 0.3 * len(det.labels)


def test_detection_is_deterministic(start_region: list) -> None:
    scene, det, _, _ = start_region[1]
    again = detect_obstacles(scene.cloud)
    assert again.obstacles == det.obstacles
    np.testing.assert_array_equal(again.labels, det.labels)


# ---- other vantage points, other worlds --------------------------------------------------


def _required(scene: Scene, m: Match, robot_x: float) -> bool:
    """An obstacle this scan can be asked for: 15 cm or more, wholly beyond the ground the
    tilt limit hides, and not in another's shadow (the scanner really saw it)."""
    near_edge = m.truth["x"] - m.truth["d"] / 2 - robot_x
    return m.truth["d"] >= 0.15 and near_edge >= scene.plan.near_m and m.seen >= 10


def test_from_mid_field_what_lies_ahead_is_found() -> None:
    """The robot halfway into the obstacle region (x = 2.3) facing +x: a second scan point
    of a mission. Layouts where the footprint would stand on an obstacle are skipped."""
    required = false = layouts = 0
    for seed in range(100, 140):
        world = MarteWorld.seeded(seed)
        if not _room_for_the_robot(world, 2.3, 1.94):
            continue
        layouts += 1
        if layouts > 8:
            break
        scene = scan_world(world, 2.3, 1.94, 0.0, seed=seed)
        matches, left = match(scene, detect_obstacles(scene.cloud).obstacles)
        false += len(left)
        for m in matches:
            if not _required(scene, m, 2.3):
                continue
            required += 1
            assert m.found is not None and m.found.kind == m.kind, (seed, m.truth, m.seen)
            assert m.position_error <= POSITION_BOUND
            assert abs(m.diameter_error) <= DIAMETER_BOUND
    assert required >= 12 and false == 0


def _room_for_the_robot(world: MarteWorld, x: float, y: float) -> bool:
    """The footprint (and 5 cm around it) is clear of every rock and crater."""
    return all(disc_overlap(x, y, 0.0, 1.3, 0.85, o.x, o.y, o.radius)[0] <= 0.0
               for o in (*world.layout.rocks, *world.layout.craters))


def test_with_a_45_degree_tilt_limit_the_blind_ground_is_the_only_loss() -> None:
    """autonomy.yaml's assumed tilt travel (45 deg) keeps the scanner from seeing the ground
    closer than 1.1 m ahead of the robot: from the start region that is the first 0.2 m of
    the obstacle region. Everything beyond is found; nothing is invented near it."""
    required = false = 0
    for seed in range(8):
        plan = sweep_plan(0.9, tilt_max_deg=45.0)
        assert plan.blind_m == pytest.approx(1.10)
        scene = scan_world(MarteWorld.seeded(seed), 0.9, 1.94, 0.0, plan=plan, seed=seed)
        matches, left = match(scene, detect_obstacles(scene.cloud).obstacles)
        false += len(left)
        for m in matches:
            if _required(scene, m, 0.9):
                required += 1
                assert m.found is not None and m.found.kind == m.kind, (seed, m.truth)
                assert m.position_error <= POSITION_BOUND
                assert abs(m.diameter_error) <= DIAMETER_BOUND
    assert required >= 25 and false == 0


@pytest.mark.parametrize(("name", "pose"), [("default", (0.9, 1.94, 0.0)),
                                            ("narrow-gap", (0.85, 1.2, 2.0))])
def test_world_file_layouts_are_found(name: str, pose: tuple[float, float, float]) -> None:
    world = MarteWorld(layout=load_world(f"examples/worlds/{name}.yaml"), seed=11)
    scene = scan_world(world, *pose, seed=11)
    matches, left = match(scene, detect_obstacles(scene.cloud).obstacles)
    assert left == []
    for m in matches:
        if m.truth["d"] >= 0.15:
            assert m.found is not None and m.found.kind == m.kind, m.truth
            assert m.position_error <= POSITION_BOUND
            assert abs(m.diameter_error) <= DIAMETER_BOUND


def test_the_obstacle_region_flag_drops_what_lies_in_the_digging_region() -> None:
    layout = Layout(rocks=(Rock(3.2, 1.2, 0.25, 0.15), Rock(4.9, 2.6, 0.28, 0.17)),
                    craters=(Crater(2.5, 2.8, 0.25, 0.2),), start=StartSpec("left", 0.0))
    world = MarteWorld(layout=layout, seed=12)
    scene = scan_world(world, 0.9, 1.94, 0.0, plan=sweep_plan(0.9, far_margin_m=1.5), seed=12)
    everywhere = detect_obstacles(scene.cloud).obstacles
    assert sorted((o.kind, round(o.x, 1), round(o.y, 1)) for o in everywhere) == [
        ("crater", 2.5, 2.8), ("rock", 3.2, 1.2), ("rock", 4.9, 2.6)]
    region = detect_obstacles(scene.cloud, obstacle_region_only=True).obstacles
    assert [o for o in everywhere if o.x < 4.44] == region


def test_a_pose_a_few_cm_and_a_degree_off_moves_the_obstacles_but_makes_no_walls_rocks(
) -> None:
    """The localizer's pose is good to 5 cm / 2 deg (issue 15): the walls then stand off
    their map lines in the cloud; the detector finds them where they are and drops them."""
    false = 0
    for seed in range(6):
        world = MarteWorld.seeded(seed)
        scene = scan_world(world, 0.9, 1.94, 0.0, seed=seed)
        shifted = scan_world(world, 0.9, 1.94, 0.0, seed=seed)
        cloud = _moved(shifted.cloud, 0.04, -0.04, math.radians(1.5))
        matches, left = match(scene, detect_obstacles(cloud).obstacles, reach=0.15)
        false += len(left)
        assert all(m.found is not None for m in matches if m.truth["d"] >= 0.15)
    assert false == 0


def _moved(cloud: Cloud, dx: float, dy: float, dyaw: float) -> Cloud:
    """The cloud as a pose (x + dx, y + dy, yaw + dyaw) would have placed it."""
    x, y, yaw = cloud.pose
    c, s = math.cos(dyaw), math.sin(dyaw)

    def move(p: np.ndarray) -> np.ndarray:
        rel = p[:, :2] - (x, y)
        out = p.copy()
        out[:, 0] = x + dx + c * rel[:, 0] - s * rel[:, 1]
        out[:, 1] = y + dy + s * rel[:, 0] + c * rel[:, 1]
        return out

    return replace(cloud, points=move(cloud.points), origins=move(cloud.origins),
                   pose=(x + dx, y + dy, yaw + dyaw))


def test_a_wobbling_ahrs_is_levelled_out_scan_by_scan() -> None:
    """0.15 deg of scan-to-scan attitude noise moves a far line's ground by 8 mm, as much as
    a far crater's wall is seen below it: without levelling each scan on the ground, some
    of these layouts' craters are lost or mis-measured (2-3); with it, none."""
    failures = {0: 0, 2: 0}
    for seed in range(4):
        scene = scan_world(MarteWorld.seeded(seed), 0.9, 1.94, 0.0, seed=seed, wobble_deg=0.15)
        for rounds in failures:
            found = detect_obstacles(scene.cloud, DetectionParams(level_rounds=rounds))
            matches, left = match(scene, found.obstacles)
            failures[rounds] += len(left) + sum(
                m.found is None or m.found.kind != m.kind
                or abs(m.diameter_error) > DIAMETER_BOUND or m.position_error > POSITION_BOUND
                for m in matches if m.truth["d"] >= 0.15)
    assert failures[2] == 0 and failures[0] >= 2


def test_a_corner_seen_from_the_start_does_not_tilt_the_wall_behind_into_the_arena() -> None:
    """Returns of the side walls near the corners lie within the x = 0 wall's search band;
    fitted with the few of that wall itself, they once made a line across the arena, and
    every return behind it (two rocks 0.9 m ahead of the robot) was dropped as wall."""
    world = MarteWorld.seeded(127)
    scene = scan_world(world, 0.765, 1.367, 0.0, seed=127)
    cloud = scene.cloud
    z = cloud.ground_z + 0.9
    corner = [(x, 3.88, z) for x in np.arange(0.0, 0.30, 0.01)]  # the y = 3.88 wall
    corner += [(x, 0.0, z) for x in np.arange(0.24, 0.30, 0.01)]  # the y = 0 wall
    behind = [(0.0, y, z) for y in np.arange(0.06, 0.21, 0.01)]  # the x = 0 wall itself
    points = np.vstack([cloud.points, np.array(corner + behind)])
    seen = wall_offsets(replace(cloud, points=points), DetectionParams())[0]
    if seen is not None:  # the wall where it is, within the search band along its length
        offset, slope = seen
        assert abs(offset) < 0.05 and abs(offset + slope * 3.88) < 0.05
    found = detect_obstacles(cloud).obstacles
    near = sorted((round(o.x, 1), round(o.y, 1)) for o in found if o.kind == "rock"
                  and o.x < 2.0)
    assert near == [(1.7, 1.4), (1.7, 1.8), (1.9, 2.8)]
