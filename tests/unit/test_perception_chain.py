"""Issue "Perception", done when: checked through the whole chain on the virtual clock.

Every case runs `ramp sim perceive`'s flow on the rig: the world, the Hokuyo emulator over
SCIP/TCP to the real driver, the IMU and servo emulators behind the `sim` drivers, the AHRS,
the gimbal leveller, the scan records, the localizer, the stop-and-go sweep and the detector
(`tests/perception_campaign.py`). A representative subset runs here (about 1 s a case); the
full campaign (10 seeds of every start box and heading, 40 random poses, 40 faulty runs, 40
obstacle layouts) is `python -m tests.perception_campaign --seeds 10`, its figures in the
README. The pure modules have their own thorough tests.
"""

from __future__ import annotations

import math

import pytest

from tests.perception_campaign import (
    BOXES,
    FAULT_POSITION_M,
    FAULT_YAW_DEG,
    HEADINGS,
    MOMENTS,
    OBSTACLE_D_M,
    OBSTACLE_POSITION_M,
    RANDOM_POSITION_M,
    RANDOM_YAW_DEG,
    START_POSITION_M,
    START_YAW_DEG,
    Case,
    faulty,
    obstacle_scan,
    random_pose,
    start_box,
)


def honest(case: Case) -> Case:
    """Never a confident wrong pose; a loss says why."""
    assert not case.confident_and_wrong, case
    if case.lost:
        assert case.reason and math.isnan(case.position_error_m)
    return case


@pytest.mark.parametrize("heading", HEADINGS)
@pytest.mark.parametrize("box", BOXES)
def test_from_every_start_box_and_heading_within_5cm_and_2deg(box: str, heading: int) -> None:
    seed = HEADINGS.index(heading) + 4 * BOXES.index(box)  # a different layout each
    case = honest(start_box(seed, box, heading))
    assert case.within(START_POSITION_M, START_YAW_DEG), case
    assert case.relevels == 0  # no fault: nothing to re-level


@pytest.mark.parametrize("seed", [1000, 1001, 1002, 1003])
def test_anywhere_with_the_ahrs_yaw_30deg_off_within_10cm_and_3deg_or_lost(seed: int) -> None:
    case = honest(random_pose(seed))
    assert case.lost or case.within(RANDOM_POSITION_M, RANDOM_YAW_DEG), case


@pytest.mark.parametrize("moment", list(MOMENTS))
def test_an_imu_shift_at_any_moment_is_re_levelled_or_lost_never_believed(moment: str) -> None:
    for seed in (2000, 2001):  # a random pose, a start box
        case = honest(faulty(seed, "imu-shift", moment))
        lo, hi = MOMENTS[moment]
        assert case.fault_at_s is not None and lo <= case.fault_at_s <= hi
        assert case.lost or case.within(FAULT_POSITION_M, FAULT_YAW_DEG), case
        if moment == "before-settle":  # the AHRS settled on the shifted IMU: the scan fixed it
            assert case.relevels >= 1, case


def test_with_a_drifting_gyro_within_10cm_and_5deg() -> None:
    case = honest(faulty(2002, "gyro-drift"))
    assert case.within(FAULT_POSITION_M, FAULT_YAW_DEG), case


def test_facing_a_wall_the_floor_to_the_sides_finds_level_after_an_imu_shift() -> None:
    # left box facing the x = 0 wall: no floor ahead, the AHRS settled 7 deg off
    case = honest(faulty(2009, "imu-shift", "before-settle"))
    assert case.setup == "left 180" and case.relevels >= 1
    assert case.within(FAULT_POSITION_M, FAULT_YAW_DEG), case


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_every_rock_and_crater_of_15cm_found_and_measured_none_invented(seed: int) -> None:
    case = honest(obstacle_scan(seed))
    assert case.within(START_POSITION_M, START_YAW_DEG), case
    assert case.required >= 3 and case.found == case.required, case.misses
    assert case.worst_obstacle_position_m <= OBSTACLE_POSITION_M
    assert case.worst_obstacle_d_m <= OBSTACLE_D_M
    assert case.confused == 0 and case.false == 0
