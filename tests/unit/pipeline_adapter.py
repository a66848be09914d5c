"""The real localizer and obstacle detector behind `pipeline.py`'s two signatures.

`ramp.autonomy.perception.pipeline` is the one place the autonomy calls perception through;
wiring the localizer (`localizer.localize`, one record at a time, its own `Localization`)
and the detector (`cloud.merge` + `obstacles.detect_obstacles`) into it is another piece of
work. Until it lands, the mission's whole-run tests hand `Autonomy` these two functions of
the pipeline's signatures, which call the real modules: nothing here knows the truth.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ramp.autonomy.perception import localizer as loc_mod
from ramp.autonomy.perception.cloud import merge
from ramp.autonomy.perception.obstacles import detect_obstacles
from ramp.autonomy.perception.pipeline import LevelHint, Localization, Obstacle, PoseEstimate
from ramp.autonomy.perception.records import ScanRecord

PRIOR_SIGMA_M = 0.10
PRIOR_SIGMA_YAW = math.radians(5.0)
SCANS = 3  # the newest of the level scans, localized each; they must agree


def localize(records: Sequence[ScanRecord], *, hint: str | None = None,
             yaw_prior: float | None = None,
             prior_pose: tuple[float, float, float] | None = None) -> Localization:
    prior = None
    if prior_pose is not None:
        cov = np.diag([PRIOR_SIGMA_M ** 2, PRIOR_SIGMA_M ** 2, PRIOR_SIGMA_YAW ** 2])
        prior = loc_mod.PosePrior(loc_mod.Pose(*prior_pose), cov)
    poses: list[PoseEstimate] = []
    level: LevelHint | None = None
    for record in list(records)[-SCANS:]:
        res = loc_mod.localize(record, hint=hint, yaw_prior=yaw_prior, prior=prior)
        rl = res.relevel
        if rl is not None and rl.found:
            level = LevelHint(rl.roll, rl.pitch, 1.0, record.t)
        if res.lost or res.pose is None:
            return Localization(None, True, (), res.reason, level)
        poses.append(PoseEstimate(res.pose.x, res.pose.y, res.pose.yaw, res.confidence))
    x = float(np.mean([p.x for p in poses]))
    y = float(np.mean([p.y for p in poses]))
    yaw = math.atan2(sum(math.sin(p.yaw) for p in poses), sum(math.cos(p.yaw) for p in poses))
    conf = min(p.confidence for p in poses)
    return Localization(PoseEstimate(x, y, yaw, conf), False, tuple(poses), "", level)


def detect(records: Sequence[ScanRecord], pose: PoseEstimate) -> list[Obstacle]:
    found = detect_obstacles(merge(records, pose.x, pose.y, pose.yaw)).obstacles
    return list(found)  # type: ignore[arg-type]


def run_mission(seed: int, start_box: str, heading: int, fault: str = "none",
                duration: float = 600.0) -> dict[str, Any]:
    """`ramp.simulation.mission.run_mission` with the two calls above behind the pipeline,
    for `ramp sim campaign --mission tests.unit.pipeline_adapter:run_mission` (each worker
    process wires its own)."""
    from ramp.autonomy.perception import pipeline
    from ramp.simulation.mission import run_mission as run

    pipeline.localize = localize
    pipeline.detect_obstacles = detect
    return run(seed, start_box, heading, fault, duration)
