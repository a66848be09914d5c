"""What every activity works with: one `Kit`, made once per run and shared.

The robot over MCP (`RobotLink`), the autonomy's own sensing (`Perception`: LIDAR, IMU, gimbal,
AHRS, scan records, odometry), the pose between fixes (`PoseTracker`), the config, and the two
perception calls (`pipeline.localize` and `pipeline.detect_obstacles` unless a test hands in
others of the same signatures). Also the few things the activities learn for each other that
are not the mission's business (the last localization, the planners), under names kept here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from ramp.autonomy import arena
from ramp.autonomy.config import AutonomyConfig
from ramp.autonomy.executive.pose import PoseTracker
from ramp.autonomy.executive.robot import RobotLink
from ramp.autonomy.executive.settings import ExecutiveSettings, settings_from
from ramp.autonomy.perception import pipeline
from ramp.autonomy.perception.coverage import GroundCoverage
from ramp.autonomy.perception.pipeline import Localization, Obstacle, PoseEstimate
from ramp.autonomy.perception.records import ScanRecord
from ramp.autonomy.perception.stack import Perception
from ramp.autonomy.planning import FollowerConfig, Pose

Localize = Callable[..., Localization]
Detect = Callable[[Sequence[ScanRecord], PoseEstimate], list[Obstacle]]
#: (records, pose, coverage so far or None) -> the coverage with the sweep's returns added.
Cover = Callable[[Sequence[ScanRecord], PoseEstimate, GroundCoverage | None], GroundCoverage]


@dataclass
class Kit:
    """The executive's tools (see the module docstring)."""

    robot: RobotLink
    perception: Perception
    tracker: PoseTracker
    config: AutonomyConfig
    settings: ExecutiveSettings = field(default_factory=ExecutiveSettings)
    localize: Localize = pipeline.localize
    detect: Detect = pipeline.detect_obstacles
    start_box: str | None = None  # told before the run; None: try both (see sensing.py)
    cover: Cover = pipeline.ground_coverage
    #: Everything drawn for `--plot`: paths planned and driven, obstacles detected.
    log: dict[str, Any] = field(default_factory=lambda: {
        "planned": [], "obstacles": [], "localizations": []})

    @classmethod
    def build(cls, robot: RobotLink, perception: Perception, config: AutonomyConfig, *,
              localize: Localize | None = None, detect: Detect | None = None,
              start_box: str | None = None) -> Kit:
        settings = settings_from(config.mission)
        tracker = PoseTracker(perception.odometry, perception.ahrs,
                              decay_m=settings.pose_decay_m)
        if start_box is not None and start_box not in arena.START_BOXES:
            raise ValueError(f"start box {start_box!r} is not one of "
                             f"{', '.join(arena.START_BOXES)}")
        return cls(robot, perception, tracker, config, settings,
                   localize or pipeline.localize, detect or pipeline.detect_obstacles,
                   start_box)

    @property
    def clock_now(self) -> float:
        return self.robot.clock.now()

    def follower_config(self, **changes: float) -> FollowerConfig:
        return replace(FollowerConfig(max_speed_pct=self.settings.drive_speed_pct), **changes)

    def pose(self) -> Pose | None:
        return self.tracker.estimate()


def yaw_error(a: float, b: float) -> float:
    """|a - b| the short way, radians."""
    return abs(math.remainder(a - b, 2 * math.pi))
