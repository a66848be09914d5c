"""Seeded arena layouts and start poses follow SPEC 6.1's rules, on many seeds."""

from __future__ import annotations

import math

import pytest

from firmware_like.arena import (
    HEADINGS_DEG,
    START_BOXES,
    Layout,
    Rock,
    StartSpec,
    box_bounds,
    disc_overlap,
    footprint_corners,
    random_layout,
    rule_problems,
    start_pose,
)
from firmware_like.arena_params import ArenaParams
from firmware_like.marte_params import MarteParams

SEEDS = range(300)


@pytest.fixture(scope="module")
def layouts() -> list[Layout]:
    return [random_layout(seed) for seed in SEEDS]


def test_seeded_layouts_have_three_rocks_and_two_craters_of_legal_size(
        layouts: list[Layout]) -> None:
    for layout in layouts:
        assert len(layout.rocks) == 3 and len(layout.craters) == 2
        for rock in layout.rocks:
            assert 0.10 <= rock.d <= 0.30
            assert rock.height >= rock.d / 2  # at least half as tall as wide
        for crater in layout.craters:
            assert 0.15 <= crater.d <= 0.30
            assert 0.0 < crater.depth <= 0.30


def test_seeded_obstacles_lie_wholly_in_the_obstacle_region_without_overlap(
        layouts: list[Layout]) -> None:
    for layout in layouts:
        discs = [(o.x, o.y, o.d / 2) for o in (*layout.rocks, *layout.craters)]
        for x, y, r in discs:
            assert x - r >= 1.5 and x + r < 4.44
            assert y - r >= 0.0 and y + r <= 3.88
        for i, (xa, ya, ra) in enumerate(discs):
            for xb, yb, rb in discs[i + 1:]:
                assert math.hypot(xa - xb, ya - yb) > ra + rb


def test_seeded_layouts_pass_the_rule_check_and_vary(layouts: list[Layout]) -> None:
    for seed, layout in zip(SEEDS, layouts, strict=True):
        assert rule_problems(layout, seed) == []
    assert len({layout.rocks[0].x for layout in layouts}) == len(layouts)
    assert {layout.start.box for layout in layouts if layout.start} == set(START_BOXES)
    assert {layout.start.heading_deg for layout in layouts if layout.start} == {
        float(h) for h in HEADINGS_DEG}


def test_the_same_seed_gives_the_same_layout() -> None:
    assert random_layout(42) == random_layout(42)
    assert random_layout(42) != random_layout(43)
    fixed = random_layout(42, start_box="right", heading_deg=180)
    assert fixed.rocks == random_layout(42).rocks
    assert fixed.start == StartSpec("right", 180.0)


@pytest.mark.parametrize("box", START_BOXES)
@pytest.mark.parametrize("heading", HEADINGS_DEG)
def test_start_poses_stay_in_the_box_within_ten_degrees_and_twenty_cm(box: str,
                                                                       heading: int) -> None:
    mp, ap = MarteParams(), ArenaParams()
    x0, x1, y0, y1 = box_bounds(box, mp, ap)
    centre = ((x0 + x1) / 2, (y0 + y1) / 2)
    yaws = []
    for seed in range(60):
        pose = start_pose(StartSpec(box, heading), seed)
        off = math.remainder(pose.yaw_deg - heading, 360.0)
        assert abs(off) <= 10.0
        yaws.append(off)
        assert abs(pose.x - centre[0]) <= 0.2 + 1e-9 and abs(pose.y - centre[1]) <= 0.2 + 1e-9
        for cx, cy in footprint_corners(pose.x, pose.y, math.radians(pose.yaw_deg),
                                        mp.robot_length, mp.robot_width):
            assert x0 < cx < x1 and y0 <= cy < y1  # wholly inside the box, off the walls
            assert cx > 0.0 and 0.0 < cy < 3.88
    assert max(yaws) - min(yaws) > 10.0  # the seed really perturbs it


def test_a_pinned_start_keeps_its_pose() -> None:
    pose = start_pose(StartSpec("left", 90.0, x=0.8, y=3.0, yaw_deg=97.5), seed=3)
    assert pose == (0.8, 3.0, 97.5)
    partly = start_pose(StartSpec("left", 90.0, yaw_deg=80.0), seed=3)
    assert partly.yaw_deg == 80.0 and 1.94 < partly.y < 3.88


def test_rule_check_names_what_departs_from_the_rules() -> None:
    layout = Layout(rocks=(Rock(2.0, 1.0, 0.5, 0.1), Rock(2.1, 1.0, 0.2, 0.15),
                           Rock(5.0, 1.0, 0.2, 0.15)), craters=())
    problems = rule_problems(layout)
    text = "\n".join(problems)
    assert "0 craters" in text
    assert "rocks[0]: diameter 0.500" in text
    assert "rocks[0]: 0.100 m tall" in text
    assert "rocks[2]: not wholly inside the obstacle region" in text
    assert "rocks[0] and rocks[1] overlap" in text


def test_disc_overlap_measures_depth_and_the_way_out() -> None:
    # Footprint 1.2 x 0.75 at the origin facing +x; a disc of radius 0.1 ahead of it.
    depth, nx, ny = disc_overlap(0.0, 0.0, 0.0, 1.2, 0.75, 0.65, 0.0, 0.1)
    assert depth == pytest.approx(0.05) and (nx, ny) == pytest.approx((-1.0, 0.0))
    depth, nx, ny = disc_overlap(0.0, 0.0, math.pi / 2, 1.2, 0.75, 0.0, 0.65, 0.1)
    assert depth == pytest.approx(0.05) and (nx, ny) == pytest.approx((0.0, -1.0))
    depth, _, _ = disc_overlap(0.0, 0.0, 0.0, 1.2, 0.75, 0.8, 0.6, 0.1)
    assert depth < 0.0
    depth, nx, ny = disc_overlap(0.0, 0.0, 0.0, 1.2, 0.75, 0.0, 0.3, 0.1)  # centre inside
    assert depth == pytest.approx(0.1 + 0.075) and (nx, ny) == pytest.approx((0.0, -1.0))


def test_the_simulator_and_the_autonomy_share_the_arena_s_numbers() -> None:
    from ramp.autonomy import arena

    mp, ap = MarteParams(), ArenaParams()
    assert mp.arena_length == arena.ARENA_LENGTH_M
    assert mp.arena_width == arena.ARENA_WIDTH_M
    assert ap.wall_height >= arena.WALL_HEIGHT_M
    assert mp.start_region_end == arena.START_END_X_M
    assert ap.start_split_y == arena.START_SPLIT_Y_M
    assert mp.dig_region_start == arena.OBSTACLE_END_X_M
    assert mp.collector_y == arena.COLLECTOR_Y_M
    assert mp.collector_width == arena.COLLECTOR_WIDTH_M
    assert mp.robot_length == arena.ROBOT_LENGTH_M
    assert mp.robot_width == arena.ROBOT_WIDTH_M
    assert tuple(arena.START_BOXES) == START_BOXES
    assert tuple(arena.HEADINGS_DEG) == HEADINGS_DEG
