"""The pose tracker learns how much ground odometry's metre covers, from its fixes: a robot
with less traction than the model (`--randomize`) is dead-reckoned short of where it is."""

from __future__ import annotations

import pytest

from ramp.autonomy.executive.pose import PoseTracker
from ramp.autonomy.odometry import Odometry

TRUE_SCALE = 0.85  # the ground covered per metre the commands say


def drive_leg(odom: Odometry, tracker: PoseTracker, t: float, seconds: float) -> float:
    """Forward at 60 % for `seconds`, then stand; returns the time after."""
    odom.command(t, 60, 0.0)
    for _ in range(round(seconds / 0.01)):
        t += 0.01
        odom.tick(t, 0.01)
        tracker.tick(t, 0.01)
    odom.stop(t)
    for _ in range(100):
        t += 0.01
        odom.tick(t, 0.01)
        tracker.tick(t, 0.01)
    return t


def test_fixes_teach_the_tracker_the_ground_s_scale() -> None:
    odom = Odometry()
    tracker = PoseTracker(odom)
    tracker.fix(0.0, 1.0, 2.0, 0.0, 1.0)
    t, true_x, errors = 0.0, 1.0, []
    for _ in range(5):
        before = odom.pose[0]
        t = drive_leg(odom, tracker, t, 6.0)
        said = odom.pose[0] - before  # what the commands say the leg was
        true_x += TRUE_SCALE * said
        assert tracker.pose is not None
        errors.append(abs(tracker.pose[0] - true_x) / said)
        tracker.fix(t, true_x, 2.0, 0.0, 1.0)
    assert errors[0] == pytest.approx(1.0 - TRUE_SCALE, abs=0.01)  # the model's scale
    assert errors[-1] < 0.02  # learnt: under 2 % of the leg off at the next fix
    assert tracker.distance_scale == pytest.approx(TRUE_SCALE, abs=0.02)


def test_an_unsure_fix_or_a_short_drive_teaches_nothing() -> None:
    odom = Odometry()
    tracker = PoseTracker(odom)
    tracker.fix(0.0, 1.0, 2.0, 0.0, 0.5)  # not sure enough to start from
    t = drive_leg(odom, tracker, 0.0, 6.0)
    tracker.fix(t, 1.5, 2.0, 0.0, 1.0)
    assert tracker.distance_scale == 1.0
    t = drive_leg(odom, tracker, t, 1.0)  # about 0.18 m
    tracker.fix(t, 1.6, 2.0, 0.0, 1.0)
    assert tracker.distance_scale == 1.0
