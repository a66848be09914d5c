"""`ramp sim perceive`'s flow: place the robot, let the sensors settle, localize, sweep, detect.

The same steps the mission takes in its Initial Localization, Prepare for Scan, Scan for
Obstacles and Detect Obstacles states (SPEC 6.3), on the simulation rig (`rig.py`): the real
LIDAR driver over SCIP/TCP, the `sim` IMU and gimbal drivers on their emulators, the AHRS,
the gimbal leveller and the scan collector, all on one virtual clock; the localizer and the
detector through `ramp.autonomy.perception.pipeline`.

1. **Place** the robot at the pose asked for (the chassis settles on the terrain there).
2. **Settle**: the AHRS measures the gyro bias and gravity while the robot stands still; the
   gimbal levels the LIDAR; the LIDAR streams. Without a start-box hint the AHRS is given the
   true yaw plus a seeded error of up to `YAW_ERROR_MAX_DEG` (the drift a run accumulates),
   which breaks the arena's symmetry as it does mid-mission; with one it has no yaw at all.
3. **Localize** (`pipeline.Tracker.initialise`) from `localize_scans` level scans (taken
   again, and the robot localized again, whenever the AHRS corrects its mount after them:
   an IMU that moves while parked is caught by the AHRS once it is still again).
4. **Sweep** (`pipeline.plan_scan`, `sweep.Sweep`): the planned tilts, stop and go, ahead of
   the robot (the obstacle region when it faces it); back to 3 if the AHRS corrected its
   mount meanwhile. A lost robot sweeps too, with the free ground its level scan shows ahead:
   the floor is how it finds level. When a wall ahead leaves too little floor in view, it
   sweeps panned to each side as well (`SIDE_PANS_DEG`), for the floor there.
5. **Level check**: where the re-leveller (step 3) or the floor (`level_from_floor`, step 4)
   says level is, against the AHRS (beyond `hint_adopt_deg` for the scan, `FLOOR_ADOPT_DEG`
   for the floor). A disagreement means the IMU moved on its mount: the AHRS
   takes the hint (`Ahrs.level_hint`: its mount correction, hence the gimbal's set-point and
   every later record), the gimbal re-levels, and the flow goes back to 3, up to
   `max_relocalize_tries` times.
6. **Detect** rocks and craters from the sweep at the pose found (`detect_obstacles`); a
   confident pose corrects the AHRS yaw. Lost: no obstacles, and the reason.

`perceive(...)` returns a `PerceiveResult`.
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from firmware_like.marte import MarteWorld
from ramp.autonomy.config import AutonomyConfig
from ramp.autonomy.mount import angle_between
from ramp.autonomy.perception import pipeline
from ramp.autonomy.perception.ahrs import up_in_chassis
from ramp.autonomy.perception.cloud import SweepPlan
from ramp.autonomy.perception.obstacles import Detection
from ramp.autonomy.perception.pipeline import LevelHint, Localization, Obstacle
from ramp.autonomy.perception.records import ScanRecord
from ramp.autonomy.perception.sweep import DONE, Sweep
from ramp.simulation.rig import Rig

YAW_ERROR_MAX_DEG = 20.0  # issue "Perception": the AHRS starts within 20 deg of the truth
SETTLE_TIMEOUT_S = 10.0  # sensors up, AHRS settled, gimbal level
SCAN_TIMEOUT_S = 3.0  # for the level scans of one localization
#: When an imu-shift may happen in this short run: from before the AHRS has settled (only the
#: scan can tell) through the level scans to the end of the first sweep (the AHRS sees the
#: jump while parked), so every moment of the flow can be hit.
SHIFT_WINDOW_S = (0.5, 12.0)
RUN_LENGTH_S = 30.0
SCAN_RETAKES = 2  # scans taken again after the AHRS corrected itself, at most
SIDE_PANS_DEG = (90.0, -90.0)  # where to look for floor when there is too little ahead


class PerceiveError(Exception):
    """The flow could not run (the sensors never came up); the message says which."""


@dataclass(frozen=True)
class LevelFix:
    """A level correction the flow handed to the AHRS: from the `scan` (re-leveller) or the
    `floor`, and by how much it disagreed with the AHRS, degrees."""

    source: str
    deg: float
    t: float


@dataclass
class PerceiveResult:
    """What one run of the flow found, beside the truth."""

    localization: Localization
    obstacles: list[Obstacle]
    true_pose: tuple[float, float, float]  # x, y (m), yaw (rad), at the end of the run
    true_obstacles: list[Obstacle]
    level_records: list[ScanRecord]
    sweep_records: list[ScanRecord] = field(default_factory=list)
    side_records: list[ScanRecord] = field(default_factory=list)  # panned, for the floor
    placed_pose: tuple[float, float, float] | None = None  # where it was put, if elsewhere
    plan: SweepPlan | None = None
    detection: Detection | None = None
    level_fixes: list[LevelFix] = field(default_factory=list)
    retakes: int = 0  # localizations done again after the AHRS corrected its mount
    yaw_prior: float | None = None  # the AHRS yaw the localizer was given, rad
    imu_suspect: bool = False
    imu_suspect_reason: str = ""
    imu_correction_deg: float = 0.0
    sweep_note: str = ""
    fault_info: dict[str, Any] = field(default_factory=dict)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    cpu_localize_s: float = 0.0  # process time in the localizer (every try)
    cpu_detect_s: float = 0.0  # in merging the sweep and detecting

    @property
    def pose(self) -> pipeline.PoseEstimate | None:
        return self.localization.pose

    @property
    def lost(self) -> bool:
        return self.localization.lost

    @property
    def relevels(self) -> int:
        return len(self.level_fixes)

    def to_json(self, **extra: Any) -> dict[str, Any]:
        """The command's JSON object (issue "Perception" part 5), plus the details."""
        def pose_doc(p: pipeline.PoseEstimate) -> dict[str, float]:
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
            "retakes": self.retakes,
            "moved_off": self._moved_off(),
            "level_fixes": [{"from": f.source, "deg": round(f.deg, 2), "t": round(f.t, 3)}
                            for f in self.level_fixes],
            "imu": {"suspect": self.imu_suspect, "reason": self.imu_suspect_reason,
                    "correction_deg": round(self.imu_correction_deg, 3),
                    **self.fault_info},
            "scans": len(self.level_records), "sweep_scans": len(self.sweep_records),
            "side_scans": len(self.side_records),
            "sweep_note": self.sweep_note,
            "sim_time_s": round(self.sim_time_s, 3), "wall_time_s": round(self.wall_time_s, 3),
            "cpu_s": {"localize": round(self.cpu_localize_s, 3),
                      "detect": round(self.cpu_detect_s, 3)},
        }


    def _moved_off(self) -> str:
        """Why the truth is not where the robot was placed (the world pushed it off a rock
        it was put on), or ""."""
        if self.placed_pose is None:
            return ""
        (x0, y0, _), (x, y, _) = self.placed_pose, self.true_pose
        shift = math.hypot(x - x0, y - y0)
        return "" if shift < 0.005 else (
            f"placed overlapping an obstacle, the robot was pushed {shift:.2f} m off it")


def true_obstacles(world: MarteWorld) -> list[Obstacle]:
    return ([Obstacle("rock", r.x, r.y, r.d) for r in world.layout.rocks]
            + [Obstacle("crater", c.x, c.y, c.d) for c in world.layout.craters])


def yaw_error(seed: int) -> float:
    """The AHRS's start error without a hint, rad: uniform within +-YAW_ERROR_MAX_DEG."""
    rng = random.Random(f"perceive-yaw-{seed}")
    return math.radians(rng.uniform(-YAW_ERROR_MAX_DEG, YAW_ERROR_MAX_DEG))


def perceive(world: MarteWorld, config: AutonomyConfig, *, seed: int = 0,
             fault: str = "none", hint: str | None = None,
             yaw_error_rad: float | None = None,
             shift_window_s: tuple[float, float] = SHIFT_WINDOW_S,
             rig_hook: Any = None) -> PerceiveResult:
    """Run the flow on `world` (the robot already where it should be); see the module doc.

    `yaw_error_rad` replaces the seeded start error of the AHRS yaw (no hint only);
    `shift_window_s` is where an `imu-shift` may fall (seconds from the start);
    `rig_hook(rig)` is called once the rig is built (tests use it to watch or disturb)."""
    wall0 = time.perf_counter()
    placed = (world.x, world.y, world.heading)
    with Rig(world, config, seed=seed, fault=fault, run_length_s=RUN_LENGTH_S,
             shift_window_s=shift_window_s) as rig:
        if rig_hook is not None:
            rig_hook(rig)
        flow = _Flow(rig, config, hint)
        ahrs = rig.ahrs
        if not rig.run_until(lambda: ahrs.time is not None, 1.0):
            raise PerceiveError(f"the IMU sent nothing: {rig.imu.fault or 'no samples'}")
        if hint is None:
            error = yaw_error(seed) if yaw_error_rad is None else yaw_error_rad
            ahrs.reset_yaw(placed[2] + error)
        if not rig.run_until(lambda: rig.perception.ready, SETTLE_TIMEOUT_S):
            raise PerceiveError(_not_ready(rig))
        result = flow.run()
        # The truth where the robot stands at the end: placed on a rock, the world pushes it
        # off in its first steps.
        result.true_pose = (world.x, world.y, world.heading)
        result.placed_pose = placed
        result.true_obstacles = true_obstacles(world)
        result.imu_suspect = ahrs.suspect
        result.imu_suspect_reason = ahrs.suspect_reason
        result.imu_correction_deg = ahrs.correction_deg
        result.fault_info = rig.imu_emulator.fault_info()
        result.sim_time_s = rig.time
    result.wall_time_s = time.perf_counter() - wall0
    return result


class _Flow:
    """Steps 3-6 of the module docstring on a settled rig."""

    def __init__(self, rig: Rig, config: AutonomyConfig, hint: str | None) -> None:
        self.rig = rig
        self.config = config
        self.hint = hint
        mission = config.mission
        self.n_scans = int(mission.get("localize_scans", 10))
        self.tries = int(mission.get("max_relocalize_tries", 3))
        self.tracker = pipeline.Tracker(odometry=rig.odometry)
        self.fixes: list[LevelFix] = []
        self.retakes = 0
        self.cpu_localize = 0.0
        self.cpu_detect = 0.0

    def run(self) -> PerceiveResult:
        ahrs = self.rig.ahrs
        relocalized = 0
        while True:
            records = self._level_scans()
            attitude = ahrs.correction  # the IMU mount the level scans were taken under
            yaw_prior = ahrs.yaw if ahrs.yaw_known else None
            cpu = time.process_time()
            loc = self.tracker.initialise(records, hint=self.hint, yaw_prior=yaw_prior)
            self.cpu_localize += time.process_time() - cpu
            if loc.level is not None and self._adopt(loc.level, "scan",
                                                     ahrs.config.hint_adopt_deg):
                continue
            result = PerceiveResult(loc, [], (0.0, 0.0, 0.0), [], records, yaw_prior=yaw_prior)
            ahead = None if loc.pose is not None else pipeline.free_ahead(records)
            result.plan = pipeline.plan_scan(self.config, loc.pose, ahead_m=ahead)
            if result.plan is None:
                result.sweep_note = "no ground to scan ahead (a wall too close)"
            else:
                sweep = self._sweep(result.plan)
                result.sweep_records = sweep.records
                if sweep.state != DONE:
                    result.sweep_note = sweep.reason
                    break
                if sweep.saturated:
                    result.sweep_note = "the tilt servo's travel clipped part of the sweep"
            if ahrs.correction != attitude and relocalized < SCAN_RETAKES:
                # The AHRS caught its IMU moving after the level scans (a jump while parked
                # is folded once the IMU is still again): they were spoiled, take them again.
                relocalized += 1
                self.retakes += 1
                continue
            floor = pipeline.level_from_floor(result.sweep_records)
            if floor is None:  # too little floor ahead (a wall): look to the sides too
                result.side_records = self._side_sweeps(loc, records)
                floor = pipeline.level_from_floor(result.sweep_records + result.side_records)
            if floor is not None and self._adopt(floor, "floor", pipeline.FLOOR_ADOPT_DEG):
                continue
            break
        result.level_fixes = list(self.fixes)
        result.retakes = self.retakes
        pose = loc.pose
        if pose is not None and not loc.lost:
            ahrs.correct_yaw(pose.yaw, pose.confidence)
            if result.sweep_records and result.plan is not None and (
                    len(result.sweep_records) == result.plan.scans):
                cpu = time.process_time()
                result.detection = pipeline.detect(result.sweep_records, pose)
                self.cpu_detect += time.process_time() - cpu
                result.obstacles = list(result.detection.obstacles)
        result.cpu_localize_s = self.cpu_localize
        result.cpu_detect_s = self.cpu_detect
        return result

    def _adopt(self, level: LevelHint, source: str, threshold_deg: float) -> bool:
        """Hand `level` to the AHRS if it disagrees by more than `threshold_deg` and tries
        are left; then re-level the gimbal. True when the flow must start again."""
        rig, ahrs = self.rig, self.rig.ahrs
        own = ahrs.attitude_at(level.t) if level.t is not None else ahrs.attitude
        off = math.degrees(angle_between(up_in_chassis(own[0], own[1]),
                                         up_in_chassis(level.roll, level.pitch)))
        if off <= threshold_deg or len(self.fixes) >= self.tries:
            return False
        ahrs.level_hint(level.roll, level.pitch, level.weight, t=level.t)
        self.fixes.append(LevelFix(source, off, rig.time))
        rig.leveller.level(0.0)
        rig.run_for(0.05)
        rig.run_until(lambda: rig.leveller.settled, SETTLE_TIMEOUT_S)
        return True

    def _level_scans(self) -> list[ScanRecord]:
        """`n_scans` records taken from now on with the gimbal settled level, taken again
        when the AHRS corrected its mount meanwhile (they straddle the correction)."""
        rig = self.rig
        for _ in range(SCAN_RETAKES + 1):
            rig.run_until(lambda: rig.leveller.settled, SETTLE_TIMEOUT_S)
            since, before = rig.clock.now(), rig.ahrs.correction
            rig.run_until(_has_scans(rig, since, self.n_scans), SCAN_TIMEOUT_S)
            records = rig.scans.since(since)[:self.n_scans]
            if not records:
                raise PerceiveError(f"no LIDAR scan arrived ({rig.lidar.state}: "
                                    f"{rig.lidar.fault or 'no fault reported'})")
            if rig.ahrs.correction == before:
                break
        return records

    def _side_sweeps(self, loc: Localization, records: list[ScanRecord]) -> list[ScanRecord]:
        """Sweeps panned to each side, for the floor there."""
        out: list[ScanRecord] = []
        for pan in SIDE_PANS_DEG:
            ahead = None if loc.pose is not None else pipeline.free_ahead(records, pan)
            plan = pipeline.plan_scan(self.config, loc.pose, ahead_m=ahead, pan_deg=pan)
            if plan is not None:
                sweep = self._sweep(plan)
                if sweep.state == DONE:
                    out.extend(sweep.records)
        return out

    def _sweep(self, plan: SweepPlan) -> Sweep:
        """The 3D scan; the gimbal level again afterwards."""
        rig = self.rig
        sweep = Sweep(rig.leveller, rig.scans, rig.pan_tilt, plan, ahrs=rig.ahrs)
        task = rig.scheduler.add_task("autonomy.sweep", rig.scheduler.rate_hz, sweep.tick)
        sweep.start(rig.clock.now())
        rig.run_until(_finished(sweep), 2.0 * plan.duration_s + 10.0)
        rig.scheduler.remove_task(task)
        sweep.cancel(rig.clock.now())
        rig.run_for(0.05)
        rig.run_until(lambda: rig.leveller.settled, SETTLE_TIMEOUT_S)
        return sweep


def _has_scans(rig: Rig, since: float, n: int) -> Callable[[], bool]:
    return lambda: len(rig.scans.since(since)) >= n


def _finished(sweep: Sweep) -> Callable[[], bool]:
    return lambda: sweep.finished


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
