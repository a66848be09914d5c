"""The two calls the perception flow makes into the localizer and the obstacle detector.

Everything around them (the rig, the AHRS, the gimbal, the scan records, the 3D sweep, the
flow of `ramp sim perceive`, the mission's states) is written against this module alone, so
the localizer and the obstacle detector can change inside without touching their callers.

    localize(records, hint=..., yaw_prior=..., prior_pose=...) -> Localization
    detect_obstacles(records, pose) -> list[Obstacle]

WAITING FOR: `ramp/autonomy/perception/localizer.py` (with `lines.py` and `relevel.py`) and
`ramp/autonomy/perception/cloud.py` + `obstacles.py`, being written beside this. Until they
are in the tree both functions raise `PerceptionUnavailable`; the flow's tests hand the flow
their own functions of the same signatures.

Conventions: arena frame of SPEC 6.1, metres and radians; `confidence` in 0..1.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass

from ramp.autonomy.perception.records import ScanRecord
from ramp.errors import RampError

START_BOXES = ("left", "right")
OBSTACLE_KINDS = ("rock", "crater")


class PerceptionUnavailable(RampError):
    """A perception stage this build does not have yet."""


@dataclass(frozen=True)
class PoseEstimate:
    """A robot pose in the arena (footprint centre, heading counter-clockwise from +x)."""

    x: float
    y: float
    yaw: float  # rad
    confidence: float = 1.0  # 0..1


@dataclass(frozen=True)
class LevelHint:
    """What the scan says about level: the chassis' roll and pitch (rad) at time `t` (the
    records' clock), with the re-leveller's confidence `weight` (0..1). Fed to
    `Ahrs.level_hint`, which corrects its idea of gravity and so the gimbal's set-point."""

    roll: float
    pitch: float
    weight: float
    t: float | None = None


@dataclass(frozen=True)
class Localization:
    """One localization: the pose, or `lost` with the reason; every pose the scan allows."""

    pose: PoseEstimate | None  # None when lost
    lost: bool
    candidates: tuple[PoseEstimate, ...] = ()  # best first (thesis fig. 5.39); may be empty
    reason: str = ""  # why lost ("too few wall points", "residual 0.31 m", ...)
    level: LevelHint | None = None  # the re-leveller's opinion, when it has one


@dataclass(frozen=True)
class Obstacle:
    """A rock (above the ground) or a crater (below it): centre and diameter, metres."""

    kind: str  # "rock" or "crater"
    x: float
    y: float
    d: float


def localize(records: Sequence[ScanRecord], *, hint: str | None = None,
             yaw_prior: float | None = None,
             prior_pose: tuple[float, float, float] | None = None) -> Localization:
    """The robot's pose from level 2D scans taken while it stood still.

    `hint`: the start box ("left" / "right") at initialisation, else None. `yaw_prior`: the
    AHRS yaw (rad) when it has one, which breaks the arena's symmetry mid-run. `prior_pose`:
    the pose odometry predicts (x, y, yaw), when there was a fix before. Never a confident
    wrong pose: `lost` with a reason instead.

    WAITING FOR `ramp.autonomy.perception.localizer`.
    """
    if hint is not None and hint not in START_BOXES:
        raise ValueError(f"hint {hint!r} is not a start box ({', '.join(START_BOXES)})")
    try:
        localizer = importlib.import_module("ramp.autonomy.perception.localizer")
    except ModuleNotFoundError as exc:
        if exc.name != "ramp.autonomy.perception.localizer":
            raise  # the module is there; something it needs is not
        raise PerceptionUnavailable(
            "the localizer (ramp/autonomy/perception/localizer.py) is not in this build "
            "yet") from exc
    result: Localization = localizer.localize(records, hint=hint, yaw_prior=yaw_prior,
                                              prior_pose=prior_pose)
    return result


def detect_obstacles(records: Sequence[ScanRecord], pose: PoseEstimate) -> list[Obstacle]:
    """Rocks and craters (arena frame) from the 3D sweep's records taken at `pose`.

    WAITING FOR `ramp.autonomy.perception.cloud` and `ramp.autonomy.perception.obstacles`.
    """
    try:
        obstacles = importlib.import_module("ramp.autonomy.perception.obstacles")
    except ModuleNotFoundError as exc:
        if exc.name != "ramp.autonomy.perception.obstacles":
            raise  # the module is there; something it needs is not
        raise PerceptionUnavailable(
            "obstacle detection (ramp/autonomy/perception/cloud.py, obstacles.py) is not in "
            "this build yet") from exc
    found: list[Obstacle] = obstacles.detect(records, pose)
    return found
