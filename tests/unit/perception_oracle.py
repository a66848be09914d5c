"""Stand-ins for the localizer and the obstacle detector that know the world's truth.

They let the perception flow (`ramp sim perceive`, the mission's first states) be tested
before the real modules exist, and they are not canned: each one checks that the records it
is handed place the LIDAR's returns where the world really is, and refuses (lost, or nothing
found) when they do not. So a test passing through them proves the rig, the drivers, the
AHRS, the gimbal and the scan records right, whatever the real localizer later does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from firmware_like.marte import MarteWorld
from ramp.autonomy.perception.ahrs import up_in_chassis
from ramp.autonomy.perception.pipeline import LevelHint, Localization, Obstacle, PoseEstimate
from ramp.autonomy.perception.records import ScanRecord

ARENA = (7.38, 3.88)


def wall_distance(points: np.ndarray) -> np.ndarray:
    x, y = points[:, 0], points[:, 1]
    return np.minimum.reduce([np.abs(x), np.abs(ARENA[0] - x), np.abs(y), np.abs(ARENA[1] - y)])


def level_error_deg(records: Sequence[ScanRecord], world: MarteWorld) -> float:
    """How far the records' attitude is from the chassis' true one, degrees."""
    r = records[-1]
    a, b = up_in_chassis(r.roll, r.pitch), up_in_chassis(world.roll, world.pitch)
    dot = max(-1.0, min(1.0, sum(x * y for x, y in zip(a, b, strict=True))))
    return math.degrees(math.acos(dot))


@dataclass
class OracleLocalizer:
    """Returns the true pose when the records fit it; the symmetric twin as a candidate."""

    world: MarteWorld
    level_tolerance_deg: float = 1.0
    calls: list[dict[str, object]] = field(default_factory=list)

    def __call__(self, records: Sequence[ScanRecord], *, hint: str | None = None,
                 yaw_prior: float | None = None,
                 prior_pose: tuple[float, float, float] | None = None) -> Localization:
        w = self.world
        self.calls.append({"n": len(records), "hint": hint, "yaw_prior": yaw_prior})
        if level_error_deg(records, w) > self.level_tolerance_deg:
            return Localization(None, True, reason="the scan is not level",
                                level=LevelHint(w.roll, w.pitch, 1.0, records[-1].t))
        pts = np.concatenate([r.points_arena(w.x, w.y, w.yaw, w.z) for r in records])
        near = wall_distance(pts) < 0.05
        if near.mean() < 0.8 or float(np.median(wall_distance(pts[near]))) > 0.02:
            return Localization(None, True, reason="the walls are not where the truth says")
        true = PoseEstimate(w.x, w.y, w.yaw, 0.95)
        twin = PoseEstimate(ARENA[0] - w.x, ARENA[1] - w.y,
                            math.remainder(w.yaw + math.pi, 2 * math.pi), 0.95)
        candidates = (true, twin)
        if hint is not None:
            in_box = [c for c in candidates if c.x < 1.5 and (c.y >= 1.94) == (hint == "left")]
            if len(in_box) != 1:
                return Localization(None, True, candidates, "the hint matches no candidate")
            return Localization(in_box[0], False, candidates)
        if yaw_prior is not None:
            best = min(candidates, key=lambda c: abs(math.remainder(c.yaw - yaw_prior,
                                                                    2 * math.pi)))
            return Localization(best, False, candidates)
        return Localization(None, True, candidates, "the arena's symmetry is not broken")


@dataclass
class OracleDetector:
    """Reports each true obstacle the sweep's returns actually show, where the truth has it."""

    world: MarteWorld
    min_points: int = 3
    calls: int = 0

    def __call__(self, records: Sequence[ScanRecord], pose: PoseEstimate) -> list[Obstacle]:
        self.calls += 1
        w = self.world
        pts = np.concatenate([r.points_arena(pose.x, pose.y, pose.yaw, w.z) for r in records])
        found = []
        for kind, items in (("rock", w.layout.rocks), ("crater", w.layout.craters)):
            for o in items:
                inside = np.hypot(pts[:, 0] - o.x, pts[:, 1] - o.y) < 0.8 * o.radius
                rel = pts[inside, 2] - w.terrain.ground(pts[inside, 0], pts[inside, 1])
                seen = rel > 0.02 if kind == "rock" else rel < -0.02
                if int(seen.sum()) >= self.min_points:
                    found.append(Obstacle(kind, o.x, o.y, o.d))
        return found
