"""`ramp sim perceive`'s flow: place the robot, let the sensors settle, localize, sweep, detect.

The same steps the mission takes in its Initial Localization, Prepare for Scan, Scan for
Obstacles and Detect Obstacles states (SPEC 6.3), on the simulation rig (`rig.py`): the real
LIDAR driver over SCIP/TCP, the `sim` IMU and gimbal drivers on their emulators, the AHRS,
the gimbal leveller and the scan collector, all on one virtual clock.

1. **Place** the robot at the pose asked for (the chassis settles on the terrain there).
2. **Settle**: the AHRS measures the gyro bias and gravity while the robot stands still; the
   gimbal levels the LIDAR; the LIDAR streams. Without a start-box hint the AHRS is given the
   true yaw plus a seeded error of up to `YAW_ERROR_MAX_DEG` (the drift a run accumulates),
   which breaks the arena's symmetry as it does mid-mission; with one it has no yaw at all.
3. **Localize** from `localize_scans` level scans (`pipeline.localize`). When the localizer
   is lost and its re-leveller says where level really is, that goes to the AHRS
   (`level_hint`, which corrects the IMU's gravity and hence the gimbal's set-point), the
   gimbal re-levels, and the scans are taken again, up to `max_relocalize_tries` times. A
   confident pose corrects the AHRS yaw.
4. **Sweep** the tilt from `sweep_start_deg` to `sweep_end_deg` below the horizon at
   `sweep_speed_dps`, keeping every scan (`sweep.TiltSweep`), then level again.
5. **Detect** rocks and craters from the sweep's records at the estimated pose
   (`pipeline.detect_obstacles`). Lost: no sweep, no obstacles.

`perceive(...)` returns a `PerceiveResult`; the localizer and the detector are parameters
(the `pipeline` functions by default) so the flow is tested on its own.
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from firmware_like.marte import MarteWorld
from ramp.autonomy.config import AutonomyConfig
from ramp.autonomy.perception import pipeline
from ramp.autonomy.perception.pipeline import Localization, Obstacle, PoseEstimate
from ramp.autonomy.perception.records import ScanRecord
from ramp.autonomy.perception.sweep import DONE, TiltSweep
from ramp.simulation.rig import Rig

YAW_ERROR_MAX_DEG = 20.0  # issue "Perception": the AHRS starts within 20 deg of the truth
SETTLE_TIMEOUT_S = 10.0  # sensors up, AHRS settled, gimbal level
SCAN_TIMEOUT_S = 3.0  # for the level scans of one localization
#: When an imu-shift may happen in this short run: from the start to just after the settle,
#: so it strikes either before the AHRS has a reference (only the scan can tell) or while the
#: robot stands parked (the AHRS sees the jump).
SHIFT_WINDOW_S = (0.5, 4.0)
RUN_LENGTH_S = 30.0

Localize = Callable[..., Localization]
Detect = Callable[[Sequence[ScanRecord], PoseEstimate], list[Obstacle]]


class PerceiveError(Exception):
    """The flow could not run (the sensors never came up); the message says which."""


@dataclass
class PerceiveResult:
    """What one run of the flow found, beside the truth."""

    localization: Localization
    obstacles: list[Obstacle]
    true_pose: tuple[float, float, float]  # x, y (m), yaw (rad)
    true_obstacles: list[Obstacle]
    level_records: list[ScanRecord]
    sweep_records: list[ScanRecord] = field(default_factory=list)
    relevels: int = 0
    yaw_prior: float | None = None  # the AHRS yaw the localizer was given, rad
    imu_suspect: bool = False
    imu_suspect_reason: str = ""
    imu_correction_deg: float = 0.0
    sweep_note: str = ""
    fault_info: dict[str, Any] = field(default_factory=dict)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0

    @property
    def pose(self) -> PoseEstimate | None:
        return self.localization.pose

    @property
    def lost(self) -> bool:
        return self.localization.lost

    def to_json(self, **extra: Any) -> dict[str, Any]:
        """The command's JSON object (issue "Perception" part 5), plus the details."""
        def pose_doc(p: PoseEstimate) -> dict[str, float]:
            return {"x": round(p.x, 4), "y": round(p.y, 4),
                    "yaw": round(math.degrees(p.yaw), 3), "confidence": round(p.confidence, 3)}

        def obstacle_doc(o: Obstacle) -> dict[str, Any]:
            return {"kind": o.kind, "x": round(o.x, 4), "y": round(o.y, 4), "d": round(o.d, 4)}

        loc = self.localization
        x, y, yaw = self.true_pose
        return {
            "pose": pose_doc(loc.pose) if loc.pose is not None and not loc.lost else None,
            "lost": bool(loc.lost),
            "obstacles": [obstacle_doc(o) for o in self.obstacles],
            "true_pose": {"x": round(x, 4), "y": round(y, 4),
                          "yaw": round(math.degrees(yaw), 3)},
            **extra,
            "reason": loc.reason,
            "candidates": [pose_doc(c) for c in loc.candidates],
            "true_obstacles": [obstacle_doc(o) for o in self.true_obstacles],
            "yaw_prior": None if self.yaw_prior is None else round(
                math.degrees(self.yaw_prior), 3),
            "relevels": self.relevels,
            "imu": {"suspect": self.imu_suspect, "reason": self.imu_suspect_reason,
                    "correction_deg": round(self.imu_correction_deg, 3),
                    **self.fault_info},
            "scans": len(self.level_records), "sweep_scans": len(self.sweep_records),
            "sweep_note": self.sweep_note,
            "sim_time_s": round(self.sim_time_s, 3), "wall_time_s": round(self.wall_time_s, 3),
        }


def true_obstacles(world: MarteWorld) -> list[Obstacle]:
    return ([Obstacle("rock", r.x, r.y, r.d) for r in world.layout.rocks]
            + [Obstacle("crater", c.x, c.y, c.d) for c in world.layout.craters])


def yaw_error(seed: int) -> float:
    """The AHRS's start error without a hint, rad: uniform within +-YAW_ERROR_MAX_DEG."""
    rng = random.Random(f"perceive-yaw-{seed}")
    return math.radians(rng.uniform(-YAW_ERROR_MAX_DEG, YAW_ERROR_MAX_DEG))


def perceive(world: MarteWorld, config: AutonomyConfig, *, seed: int = 0,
             fault: str = "none", hint: str | None = None,
             localize: Localize | None = None, detect: Detect | None = None,
             rig_hook: Callable[[Rig], None] | None = None) -> PerceiveResult:
    """Run the flow on `world` (the robot already where it should be); see the module doc.

    `localize` and `detect` default to `pipeline.localize` and `pipeline.detect_obstacles`.
    `rig_hook(rig)` is called once the rig is built (tests use it to watch or disturb)."""
    localize = localize or pipeline.localize
    detect = detect or pipeline.detect_obstacles
    wall0 = time.perf_counter()
    truth = (world.x, world.y, world.heading)
    mission = config.mission
    with Rig(world, config, seed=seed, fault=fault, run_length_s=RUN_LENGTH_S,
             shift_window_s=SHIFT_WINDOW_S) as rig:
        if rig_hook is not None:
            rig_hook(rig)
        ahrs = rig.ahrs
        # 2. settle
        if not rig.run_until(lambda: ahrs.time is not None, 1.0):
            raise PerceiveError(f"the IMU sent nothing: {rig.imu.fault or 'no samples'}")
        if hint is None:
            ahrs.reset_yaw(truth[2] + yaw_error(seed))
        if not rig.run_until(lambda: rig.perception.ready, SETTLE_TIMEOUT_S):
            raise PerceiveError(_not_ready(rig))
        # 3. localize, re-levelling when the scan says where level is
        tries = int(mission.get("max_relocalize_tries", 3))
        relevels = 0
        yaw_prior = ahrs.yaw if ahrs.yaw_known else None
        records = _level_scans(rig, int(mission.get("localize_scans", 10)))
        loc = localize(records, hint=hint, yaw_prior=yaw_prior, prior_pose=None)
        while loc.lost and loc.level is not None and relevels < tries:
            relevels += 1
            level = loc.level
            ahrs.level_hint(level.roll, level.pitch, level.weight, t=level.t)
            rig.leveller.level(0.0)
            rig.run_for(0.05)
            if not rig.run_until(lambda: rig.leveller.settled, SETTLE_TIMEOUT_S):
                break
            yaw_prior = ahrs.yaw if ahrs.yaw_known else None
            records = _level_scans(rig, int(mission.get("localize_scans", 10)))
            loc = localize(records, hint=hint, yaw_prior=yaw_prior, prior_pose=None)
        result = PerceiveResult(loc, [], truth, true_obstacles(world), records,
                                relevels=relevels, yaw_prior=yaw_prior)
        pose = loc.pose
        if pose is not None and not loc.lost:
            ahrs.correct_yaw(pose.yaw, pose.confidence)
            # 4. sweep, 5. detect
            sweep = TiltSweep(rig.leveller, rig.scans, rig.pan_tilt,
                              start_deg=float(mission.get("sweep_start_deg", 0.0)),
                              end_deg=float(mission.get("sweep_end_deg", 40.0)),
                              speed_dps=float(mission.get("sweep_speed_dps", 5.0)))
            task = rig.scheduler.add_task("autonomy.sweep", rig.scheduler.rate_hz, sweep.tick)
            sweep.start(rig.clock.now())
            rig.run_until(lambda: sweep.finished, sweep.timeout_s + 1.0)
            rig.scheduler.remove_task(task)
            sweep.cancel()
            rig.leveller.level(0.0)  # ready for the next level scans
            rig.run_for(0.05)
            rig.run_until(lambda: rig.leveller.settled, SETTLE_TIMEOUT_S)
            result.sweep_records = sweep.records
            result.sweep_note = sweep.reason if sweep.state != DONE else (
                "the gimbal saturated during the sweep" if sweep.saturated else "")
            if sweep.records:
                result.obstacles = list(detect(sweep.records, pose))
        result.imu_suspect = ahrs.suspect
        result.imu_suspect_reason = ahrs.suspect_reason
        result.imu_correction_deg = ahrs.correction_deg
        result.fault_info = rig.imu_emulator.fault_info()
        result.sim_time_s = rig.time
    result.wall_time_s = time.perf_counter() - wall0
    return result


def _level_scans(rig: Rig, n: int) -> list[ScanRecord]:
    """`n` records taken from now on with the gimbal settled level."""
    since = rig.clock.now()
    rig.run_until(lambda: len(rig.scans.since(since)) >= n, SCAN_TIMEOUT_S)
    records = rig.scans.since(since)[:n]
    if not records:
        raise PerceiveError(f"no LIDAR scan arrived ({rig.lidar.state}: "
                            f"{rig.lidar.fault or 'no fault reported'})")
    return records


def _not_ready(rig: Rig) -> str:
    p = rig.perception
    missing = []
    if not rig.imu.ready():
        missing.append(f"IMU ({rig.imu.fault})")
    if not rig.pan_tilt.ready():
        missing.append(f"gimbal ({rig.pan_tilt.fault})")
    if rig.lidar.state not in ("ready", "streaming"):
        missing.append(f"LIDAR ({rig.lidar.state}: {rig.lidar.fault})")
    if not p.ahrs.settled:
        missing.append("AHRS not settled")
    if not p.leveller.settled:
        missing.append("gimbal not level" + (" (saturated)" if p.leveller.saturated else ""))
    return f"the sensors did not come up within {SETTLE_TIMEOUT_S:g} s: " + "; ".join(missing)
