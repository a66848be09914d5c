"""3D scans of simulated arenas for the obstacle detector's tests and benchmark.

The robot stands still in a `MarteWorld`; the gimbal visits the tilts of a `SweepPlan`,
levelled against the AHRS' pitch the way the rig's gimbal does it (a tilt relative to the
horizon = the servo's tilt + the chassis pitch); each scan is `LidarView`'s ray-cast of the
world with its range noise, dust and the robot's own frame, decoded from the millimetres the
sensor sends; each `ScanRecord` carries the AHRS' roll and pitch: the world's truth plus a
fixed error plus a small scan-to-scan wobble. Everything is seeded.

The simulator's scanner sits where `LidarParams` puts it (0.40 m ahead of the footprint
centre, 0.70 m up), on the tilt axis: that is the `MOUNT` and `PIVOT` the records use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from firmware_like.arena_params import HIT_CRATER, HIT_ROCK, LidarParams
from firmware_like.lidar_view import LidarView
from firmware_like.marte import MarteWorld
from ramp.autonomy.mount import Mount, Vec3, lidar_pose
from ramp.autonomy.perception.cloud import Cloud, SweepPlan, merge, plan_sweep
from ramp.autonomy.perception.obstacles import Obstacle
from ramp.autonomy.perception.records import ScanRecord

_LP = LidarParams()
MOUNT = Mount(_LP.mount_x, _LP.mount_y, _LP.mount_z)
PIVOT: Vec3 = (_LP.mount_x, _LP.mount_y, _LP.mount_z)
OBSTACLE_END_X = 4.44  # SPEC 6.1

#: The sweep the tests use: lines every 4 cm, tilt servo as in autonomy.yaml except the
#: travel (down to 75 deg, so the first 0.2 m of the obstacle region is in view).
TILT_MAX_DEG = 75.0


def sweep_plan(robot_x: float, tilt_max_deg: float = TILT_MAX_DEG,
               spacing_m: float = 0.04, far_margin_m: float = 0.3) -> SweepPlan:
    """The sweep over the obstacle region for a robot at `robot_x` facing +x."""
    return plan_sweep(MOUNT, PIVOT, near_m=0.3, far_m=OBSTACLE_END_X + far_margin_m - robot_x,
                      spacing_m=spacing_m, tilt_max_deg=tilt_max_deg)


@dataclass
class Scene:
    """One 3D scan of one world, and the truth to judge it by."""

    world: MarteWorld
    plan: SweepPlan
    records: list[ScanRecord]
    cloud: Cloud
    kinds: np.ndarray  # what each cloud point really hit (arena_params.HIT_*)
    truth: list[tuple[str, dict[str, float]]] = field(default_factory=list)

    def seen(self, kind: str, o: dict[str, float]) -> int:
        """How many returns really came from this obstacle (0: hidden or out of view)."""
        hit = HIT_ROCK if kind == "rock" else HIT_CRATER
        p = self.cloud.points
        near = np.hypot(p[:, 0] - o["x"], p[:, 1] - o["y"]) < o["d"] / 2 + 0.02
        return int(((self.kinds == hit) & near).sum())


def scan_world(world: MarteWorld, x: float, y: float, yaw_deg: float, *,
               plan: SweepPlan | None = None, attitude_error_deg: tuple[float, float] = (
                   0.3, -0.3), wobble_deg: float = 0.05, seed: int = 0,
               digging: bool = False) -> Scene:
    """Place the robot at (x, y, yaw) (m, deg), sweep, and merge the records with the true
    pose. `attitude_error_deg` (roll, pitch) is the AHRS' fixed error, `wobble_deg` the
    standard deviation of its scan-to-scan error."""
    world.place(x, y, yaw_deg)
    plan = plan if plan is not None else sweep_plan(x)
    view = LidarView.of(world)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x3D5CA7]))
    chassis = world.chassis_pose()
    roll_est = chassis.roll + math.radians(attitude_error_deg[0])
    pitch_est = chassis.pitch + math.radians(attitude_error_deg[1])
    records: list[ScanRecord] = []
    kinds: list[np.ndarray] = []
    for i, level_tilt in enumerate(plan.tilts_deg):
        tilt = level_tilt - math.degrees(pitch_est)  # the gimbal levels the sweep
        scan = view.scan(view.pose_of_world(math.radians(plan.pan_deg), math.radians(tilt)),
                         digging=digging)
        ranges = np.where(scan.mm < 23, np.nan, scan.mm / 1000.0)  # as the driver decodes
        position, rotation = lidar_pose(MOUNT, PIVOT, plan.pan_deg, tilt)
        wobble = rng.standard_normal(2) * math.radians(wobble_deg)
        records.append(ScanRecord(
            t=0.1 * i, ranges=ranges, angles=view.angles, lidar_position=position,
            lidar_rotation=rotation, roll=roll_est + float(wobble[0]),
            pitch=pitch_est + float(wobble[1]), pan_deg=plan.pan_deg, tilt_deg=tilt))
        kinds.append(scan.kinds[np.isfinite(ranges)])
    cloud = merge(records, x, y, math.radians(yaw_deg))
    d = world.describe()
    truth = ([("rock", o) for o in d["rocks"]]  # type: ignore[attr-defined]
             + [("crater", o) for o in d["craters"]])  # type: ignore[attr-defined]
    return Scene(world, plan, records, cloud, np.concatenate(kinds), truth)


@dataclass
class Match:
    kind: str
    truth: dict[str, float]
    found: Obstacle | None
    distance_m: float  # from the scanner (the first record's optical centre), horizontally
    seen: int

    @property
    def position_error(self) -> float:
        assert self.found is not None
        return math.hypot(self.found.x - self.truth["x"], self.found.y - self.truth["y"])

    @property
    def diameter_error(self) -> float:
        assert self.found is not None
        return self.found.d - self.truth["d"]


def match(scene: Scene, obstacles: list[Obstacle], reach: float = 0.10,
          ) -> tuple[list[Match], list[Obstacle]]:
    """Each true obstacle with the detection nearest to it (of either kind, centre within
    its radius + `reach`), and the detections left over (false obstacles)."""
    left = list(obstacles)
    out: list[Match] = []
    origin = scene.cloud.origins[0]
    for kind, o in scene.truth:
        near = [q for q in left if math.hypot(q.x - o["x"], q.y - o["y"]) < o["d"] / 2 + reach]
        best = min(near, key=lambda q: math.hypot(q.x - o["x"], q.y - o["y"]), default=None)
        if best is not None:
            left.remove(best)
        out.append(Match(kind, o, best, math.hypot(o["x"] - origin[0], o["y"] - origin[1]),
                         scene.seen(kind, o)))
    return out, left
