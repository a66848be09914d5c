"""The whole perception chain judged against the truth: the bounds of issue "Perception".

Each case runs `ramp sim perceive`'s flow (`ramp.simulation.perceive.perceive`) on the rig -
world, LIDAR/IMU/servo emulators, the real SCIP, IMU and servo drivers, AHRS, gimbal, scan
records, localizer, stop-and-go sweep, detector - on the virtual clock, seeded, and scores it:

- `start_box(seed, box, heading)`: the seeded start pose, the box as the hint;
- `random_pose(seed)`: anywhere in the arena off the obstacles, any heading, no hint, the
  AHRS yaw up to 30 deg off;
- `faulty(seed, fault, moment)`: a random pose or a start box (by seed) with `gyro-drift` or
  an `imu-shift` at a chosen moment of the flow (`MOMENTS`);
- `obstacle_scan(seed)`: facing the obstacle region from the start region's front edge (where
  the mission scans from), every rock and crater matched to the truth.

The unit tests run a few of each (`tests/unit/test_perception_chain.py`); the full campaign
is a command (about 2 s of CPU a case):

    .venv/bin/python -m tests.perception_campaign --seeds 10 [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import random
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path

from firmware_like.arena import disc_overlap
from firmware_like.marte import MarteWorld
from ramp.autonomy.perception.pipeline import HIGH_CONFIDENCE
from ramp.simulation.perceive import PerceiveResult, perceive
from ramp.simulation.rig import load_autonomy_config

BOXES = ("left", "right")
HEADINGS = (0, 90, 180, 270)
#: When an imu-shift strikes (s from the start): before the AHRS settles (only the scan can
#: tell), during the level scans of the first localization, during the 3D sweep.
MOMENTS = {"before-settle": (0.5, 1.9), "level-scans": (2.0, 2.4), "sweep": (3.0, 11.0)}

# The bounds.
START_POSITION_M, START_YAW_DEG = 0.05, 2.0
RANDOM_POSITION_M, RANDOM_YAW_DEG = 0.10, 3.0
FAULT_POSITION_M, FAULT_YAW_DEG = 0.10, 5.0
WRONG_POSITION_M, WRONG_YAW_DEG = 0.25, 10.0  # never with high confidence
OBSTACLE_MIN_D_M, OBSTACLE_POSITION_M, OBSTACLE_D_M = 0.15, 0.10, 0.05


@dataclass
class Case:
    """One run of the flow, scored."""

    kind: str
    seed: int
    setup: str
    lost: bool
    position_error_m: float = math.nan
    yaw_error_deg: float = math.nan
    confidence: float = 0.0
    reason: str = ""
    relevels: int = 0
    level_from: str = ""  # where each level correction came from ("scan", "floor")
    retakes: int = 0  # localized again after the AHRS caught its IMU moving
    fault_at_s: float | None = None
    required: int = 0  # obstacles of 15 cm or more
    found: int = 0  # of those, within the bounds and of the right kind
    confused: int = 0
    false: int = 0
    worst_obstacle_position_m: float = 0.0
    worst_obstacle_d_m: float = 0.0
    misses: list[str] = field(default_factory=list)
    cpu_localize_s: float = 0.0
    cpu_detect_s: float = 0.0
    wall_s: float = 0.0

    @property
    def confident_and_wrong(self) -> bool:
        return (not self.lost and self.confidence >= HIGH_CONFIDENCE
                and (self.position_error_m > WRONG_POSITION_M
                     or self.yaw_error_deg > WRONG_YAW_DEG))

    def within(self, position_m: float, yaw_deg: float) -> bool:
        return (not self.lost and self.position_error_m < position_m
                and self.yaw_error_deg < yaw_deg)


def _score(kind: str, seed: int, setup: str, world: MarteWorld, r: PerceiveResult) -> Case:
    case = Case(kind, seed, setup, r.lost, reason=r.localization.reason,
                relevels=r.relevels, level_from=",".join(f.source for f in r.level_fixes),
                retakes=r.retakes, fault_at_s=r.fault_info.get("at_s"),
                cpu_localize_s=r.cpu_localize_s, cpu_detect_s=r.cpu_detect_s,
                wall_s=r.wall_time_s)
    if r.pose is not None:
        case.position_error_m = math.hypot(r.pose.x - world.x, r.pose.y - world.y)
        case.yaw_error_deg = abs(math.degrees(math.remainder(r.pose.yaw - world.yaw,
                                                             2 * math.pi)))
        case.confidence = r.pose.confidence
    return case


def _run(world: MarteWorld, seed: int, **kw: object) -> PerceiveResult:
    return perceive(world, load_autonomy_config(), seed=seed, **kw)  # type: ignore[arg-type]


def start_box(seed: int, box: str, heading: int) -> Case:
    world = MarteWorld.seeded(seed, box, heading)
    return _score("start_box", seed, f"{box} {heading}", world, _run(world, seed, hint=box))


def free_pose(world: MarteWorld, rng: random.Random) -> None:
    """Place the robot anywhere in the arena, any heading, its footprint off the obstacles."""
    obstacles = [(o.x, o.y, o.d / 2) for o in (*world.layout.rocks, *world.layout.craters)]
    while True:
        x, y, yaw = rng.uniform(0.4, 7.0), rng.uniform(0.4, 3.5), rng.uniform(-180.0, 180.0)
        try:
            world.place(x, y, yaw)
        except ValueError:
            continue
        if all(disc_overlap(world.x, world.y, world.yaw, 1.2, 0.75, *o)[0] <= 0.0
               for o in obstacles):
            return


def random_pose(seed: int, fault: str = "none",
                shift_window_s: tuple[float, float] = (0.5, 12.0)) -> Case:
    world = MarteWorld.seeded(seed)
    rng = random.Random(f"perception-campaign-{seed}")
    free_pose(world, rng)
    error = math.radians(rng.uniform(-30.0, 30.0))
    setup = (f"x {world.x:.2f} y {world.y:.2f} yaw {world.heading_deg:.0f}, AHRS yaw "
             f"{math.degrees(error):+.0f} deg")
    result = _run(world, seed, yaw_error_rad=error, fault=fault, shift_window_s=shift_window_s)
    return _score("random_pose", seed, setup, world, result)


def faulty(seed: int, fault: str, moment: str = "before-settle") -> Case:
    """A fault on a random pose (even seeds) or in a start box with its hint (odd ones)."""
    window = MOMENTS[moment]
    if seed % 2 == 0:
        case = random_pose(seed, fault, window)
    else:
        box, heading = BOXES[(seed // 2) % 2], HEADINGS[(seed // 4) % 4]
        world = MarteWorld.seeded(seed, box, heading)
        case = _score("start_box", seed, f"{box} {heading}", world,
                      _run(world, seed, hint=box, fault=fault, shift_window_s=window))
    case.kind = f"{fault} {moment}" if fault == "imu-shift" else fault
    return case


def obstacle_scan(seed: int) -> Case:
    """From the start region's front edge, facing the obstacle region (where the mission
    scans from), with the start box as the hint."""
    world = MarteWorld.seeded(seed)
    rng = random.Random(f"perception-obstacles-{seed}")
    y = 1.94 + rng.uniform(-0.3, 0.3)
    world.place(rng.uniform(0.85, 0.9), y, rng.uniform(-3.0, 3.0))
    result = _run(world, seed, hint="left" if y >= 1.94 else "right")
    case = _score("obstacles", seed, f"x {world.x:.2f} y {world.y:.2f} yaw "
                  f"{world.heading_deg:.1f}", world, result)
    left = list(result.obstacles)
    for truth in result.true_obstacles:
        near = [o for o in left if math.hypot(o.x - truth.x, o.y - truth.y) < truth.d / 2 + 0.1]
        best = min(near, key=lambda o: math.hypot(o.x - truth.x, o.y - truth.y), default=None)
        if best is not None:
            left.remove(best)
            if best.kind != truth.kind:
                case.confused += 1
        if truth.d < OBSTACLE_MIN_D_M:
            continue
        case.required += 1
        what = f"{truth.kind} d {truth.d:.2f} at ({truth.x:.2f}, {truth.y:.2f})"
        if best is None or best.kind != truth.kind:
            case.misses.append(f"{what}: not found")
            continue
        err = math.hypot(best.x - truth.x, best.y - truth.y)
        derr = abs(best.d - truth.d)
        case.worst_obstacle_position_m = max(case.worst_obstacle_position_m, err)
        case.worst_obstacle_d_m = max(case.worst_obstacle_d_m, derr)
        if err <= OBSTACLE_POSITION_M and derr <= OBSTACLE_D_M:
            case.found += 1
        else:
            case.misses.append(f"{what}: found {err * 100:.1f} cm off, d {derr * 100:+.1f} cm")
    case.false = len(left)
    return case


# ---- the campaign ---------------------------------------------------------------------------


def cases(seeds: int, first: int = 0) -> dict[str, list[Callable[[], Case]]]:
    """Every case of a campaign of `seeds` seeds per setting, by group."""
    s = range(first, first + seeds)
    return {
        "start_box": [lambda k=k, b=b, h=h: start_box(k, b, h)
                      for k in s for b in BOXES for h in HEADINGS],
        "random_pose": [lambda k=k: random_pose(1000 + k) for k in range(first, first + 4 * seeds)],
        "faults": [lambda k=k, f=f, m=m: faulty(2000 + k, f, m) for k in s
                   for f, m in (("gyro-drift", "before-settle"),
                                *(("imu-shift", m) for m in MOMENTS))],
        "obstacles": [lambda k=k: obstacle_scan(k) for k in range(first, first + 4 * seeds)],
    }


def summary(group: str, done: Iterable[Case]) -> dict[str, object]:
    """The figures of one group against its bounds."""
    done = list(done)
    fixed = [c for c in done if not c.lost]
    out: dict[str, object] = {
        "cases": len(done), "lost": len(done) - len(fixed),
        "confident_and_wrong": sum(c.confident_and_wrong for c in done),
        "worst_position_cm": round(max((c.position_error_m for c in fixed), default=0) * 100, 2),
        "worst_yaw_deg": round(max((c.yaw_error_deg for c in fixed), default=0), 2),
        "relevelled": sum(c.relevels > 0 for c in done),
        "relevelled_from_scan": sum("scan" in c.level_from for c in done),
        "relevelled_from_floor": sum("floor" in c.level_from for c in done),
        "retaken": sum(c.retakes > 0 for c in done),
        "cpu_localize_s_p50": round(sorted(c.cpu_localize_s for c in done)[len(done) // 2], 3),
    }
    if group == "start_box":
        out["outside_5cm_2deg"] = sum(not c.within(START_POSITION_M, START_YAW_DEG) for c in done)
    elif group == "random_pose":
        out["outside_10cm_3deg_not_lost"] = sum(
            not c.lost and not c.within(RANDOM_POSITION_M, RANDOM_YAW_DEG) for c in done)
    elif group == "faults":
        out["outside_10cm_5deg_not_lost"] = sum(
            not c.lost and not c.within(FAULT_POSITION_M, FAULT_YAW_DEG) for c in done)
    else:
        out.update(required=sum(c.required for c in done), found=sum(c.found for c in done),
                   confused=sum(c.confused for c in done),
                   false_per_layout=round(sum(c.false for c in done) / max(1, len(done)), 3),
                   worst_obstacle_position_cm=round(
                       max(c.worst_obstacle_position_m for c in done) * 100, 2),
                   worst_obstacle_d_cm=round(max(c.worst_obstacle_d_m for c in done) * 100, 2),
                   cpu_detect_s_p50=round(sorted(c.cpu_detect_s for c in done)[len(done) // 2],
                                          3))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.perception_campaign",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds per setting (default 10)")
    ap.add_argument("--first", type=int, default=0, help="first seed")
    ap.add_argument("--only", default="", help="groups, comma-separated (default: all)")
    ap.add_argument("--json", action="store_true", help="one JSON object on the last line")
    ap.add_argument("--cases", type=Path, help="write every case as JSON lines here")
    args = ap.parse_args(argv)
    groups = cases(args.seeds, args.first)
    wanted = [g for g in args.only.split(",") if g] or list(groups)
    report: dict[str, object] = {}
    rows: list[dict[str, object]] = []
    t0 = time.perf_counter()
    for group in wanted:
        done = []
        for k, run in enumerate(groups[group]):
            case = run()
            done.append(case)
            rows.append({"group": group, **asdict(case)})
            bad = case.confident_and_wrong or case.misses or case.confused
            if bad or not args.json:
                print(f"{group} {k + 1}/{len(groups[group])}: {case.kind} seed {case.seed} "
                      f"{case.setup}: " + ("LOST " + case.reason if case.lost else
                                           f"{case.position_error_m * 100:.2f} cm "
                                           f"{case.yaw_error_deg:.2f} deg conf "
                                           f"{case.confidence:.2f}")
                      + (f"; {case.relevels} re-level(s)" if case.relevels else "")
                      + (f"; {'; '.join(case.misses)}" if case.misses else "")
                      + (f"; {case.false} false" if case.false else ""), file=sys.stderr)
        report[group] = summary(group, done)
    report["wall_s"] = round(time.perf_counter() - t0, 1)
    if args.cases:
        args.cases.write_text("".join(json.dumps(r) + "\n" for r in rows))
    print(json.dumps(report) if args.json else json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
