"""`ramp sim mission --record FILE.mcap`: the autonomy's view of a run, for Foxglove (SPEC 8).

Written with the flight recorder (`ramp.recorder.Recorder`: its writer thread, its MCAP
framing), on channels of Foxglove's own schemas where Foxglove has one, so its 3D panel,
Plot and State Transitions panels show them without a plugin:

| topic | schema | one message per |
|---|---|---|
| `/mission/state` | `ramp.MissionState` | state change: state, from, trigger, reason |
| `/pose/true` | `foxglove.PoseInFrame` | 0.1 s: the world's truth (frame `arena`) |
| `/pose/estimated` | `foxglove.PoseInFrame` | 0.1 s while the autonomy has a pose |
| `/mission/numbers` | `ramp.MissionNumbers` | 0.1 s: pose confidence, bin load, delivered, lift |
| `/lidar/scan` | `foxglove.LaserScan` | each scan the autonomy took, at the estimated pose |
| `/map` | `foxglove.SceneUpdate` | when the map changes: walls, detected obstacles, the plan |

Times: the simulation's clock, mapped to wall-clock nanoseconds once at the start (the
recorder's `TimeBase`). What is left for the backend's side (every MCP message, the get rows,
the driver commands) comes with the recorder's integration into the supervisor
(`ramp run --record`); the same file would then carry both.
"""

from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ramp.recorder.config import RecorderConfig
from ramp.recorder.recorder import Recorder
from ramp.recorder.schemas import ChannelSpec

if TYPE_CHECKING:
    from ramp.autonomy.perception.records import ScanRecord
    from ramp.simulation.mission import MissionRun
    from ramp.statemachine import StateChange

FRAME = "arena"

_TIME = {"type": "object", "title": "time",
         "properties": {"sec": {"type": "integer", "minimum": 0},
                        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}}
_VEC3 = {"type": "object", "title": "foxglove.Vector3",
         "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT = {"type": "object", "title": "foxglove.Quaternion",
         "properties": {k: {"type": "number"} for k in "xyzw"}}
_POSE = {"type": "object", "title": "foxglove.Pose",
         "properties": {"position": _VEC3, "orientation": _QUAT}}
_COLOR = {"type": "object", "title": "foxglove.Color",
          "properties": {k: {"type": "number"} for k in ("r", "g", "b", "a")}}
_POINT3 = {"type": "object", "title": "foxglove.Point3",
           "properties": {k: {"type": "number"} for k in "xyz"}}

POSE_IN_FRAME = {"title": "foxglove.PoseInFrame", "type": "object",
                 "description": "A timestamped pose for an object or reference frame in 3D",
                 "properties": {"timestamp": _TIME, "frame_id": {"type": "string"},
                                "pose": _POSE}}
LASER_SCAN = {"title": "foxglove.LaserScan", "type": "object",
              "description": "A single scan from a planar laser range-finder",
              "properties": {"timestamp": _TIME, "frame_id": {"type": "string"},
                             "pose": _POSE, "start_angle": {"type": "number"},
                             "end_angle": {"type": "number"},
                             "ranges": {"type": "array", "items": {"type": "number"}},
                             "intensities": {"type": "array", "items": {"type": "number"}}}}
SCENE_UPDATE = {
    "title": "foxglove.SceneUpdate", "type": "object",
    "description": "An update to the entities displayed in a 3D scene",
    "properties": {
        "deletions": {"type": "array", "items": {"type": "object"}},
        "entities": {"type": "array", "items": {
            "type": "object", "title": "foxglove.SceneEntity",
            "properties": {
                "timestamp": _TIME, "frame_id": {"type": "string"}, "id": {"type": "string"},
                "lifetime": {"type": "object", "title": "duration",
                             "properties": {"sec": {"type": "integer"},
                                            "nsec": {"type": "integer"}}},
                "frame_locked": {"type": "boolean"},
                "metadata": {"type": "array", "items": {"type": "object"}},
                "cylinders": {"type": "array", "items": {
                    "type": "object", "title": "foxglove.CylinderPrimitive",
                    "properties": {"pose": _POSE, "size": _VEC3,
                                   "bottom_scale": {"type": "number"},
                                   "top_scale": {"type": "number"}, "color": _COLOR}}},
                "lines": {"type": "array", "items": {
                    "type": "object", "title": "foxglove.LinePrimitive",
                    "properties": {"type": {"type": "integer"}, "pose": _POSE,
                                   "thickness": {"type": "number"},
                                   "scale_invariant": {"type": "boolean"},
                                   "points": {"type": "array", "items": _POINT3},
                                   "color": _COLOR,
                                   "colors": {"type": "array", "items": _COLOR},
                                   "indices": {"type": "array",
                                               "items": {"type": "integer"}}}}}}}}}}
MISSION_STATE = {"title": "ramp.MissionState", "type": "object",
                 "description": "The mission machine's state change (SPEC 6.3)",
                 "properties": {"state": {"type": "string"}, "from": {"type": "string"},
                                "trigger": {"type": "string"}, "reason": {"type": "string"}},
                 "required": ["state", "from", "trigger", "reason"]}
MISSION_NUMBERS = {"title": "ramp.MissionNumbers", "type": "object",
                   "description": "What the mission believes and what is true, 10 Hz",
                   "properties": {k: {"type": ["number", "null"]} for k in (
                       "pose_confidence", "bin_kg", "true_bin_kg", "delivered_kg",
                       "lift", "localization_losses")}}

CHANNELS = (
    ChannelSpec("/mission/state", "ramp.MissionState", MISSION_STATE),
    ChannelSpec("/pose/true", "foxglove.PoseInFrame", POSE_IN_FRAME),
    ChannelSpec("/pose/estimated", "foxglove.PoseInFrame", POSE_IN_FRAME),
    ChannelSpec("/mission/numbers", "ramp.MissionNumbers", MISSION_NUMBERS),
    ChannelSpec("/lidar/scan", "foxglove.LaserScan", LASER_SCAN),
    ChannelSpec("/map", "foxglove.SceneUpdate", SCENE_UPDATE),
)


def _yaw_quat(yaw: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def _matrix_quat(m: np.ndarray) -> dict[str, float]:
    """A rotation matrix as a unit quaternion (Shepperd's method)."""
    t = float(np.trace(m))
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        return {"w": 0.25 * s, "x": (m[2, 1] - m[1, 2]) / s, "y": (m[0, 2] - m[2, 0]) / s,
                "z": (m[1, 0] - m[0, 1]) / s}
    i = int(np.argmax(np.diag(m)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(max(1e-12, 1.0 + m[i, i] - m[j, j] - m[k, k])) * 2
    q = [0.0, 0.0, 0.0]
    q[i] = 0.25 * s
    q[j] = (m[j, i] + m[i, j]) / s
    q[k] = (m[k, i] + m[i, k]) / s
    return {"x": q[0], "y": q[1], "z": q[2], "w": (m[k, j] - m[j, k]) / s}


class MissionRecorder:
    """A `MissionRun` observer writing the channels above into one MCAP file."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._dir = Path(tempfile.mkdtemp(prefix="ramp-mission-rec-"))
        self.recorder = Recorder(RecorderConfig(str(self._dir), max_mb=1e6, keep=1))
        for spec in CHANNELS:
            self.recorder.add_channel(spec)
        self._map_key: tuple[int, int] = (-1, -1)
        self._run: MissionRun | None = None

    # -- MissionRun's hooks ---------------------------------------------------------------------
    def started(self, run: MissionRun) -> None:
        assert run.rig is not None
        self._run = run
        self.recorder.start(run.rig.clock.now())
        run.rig.perception.scans.add_listener(self._scan)

    def changed(self, run: MissionRun, change: StateChange) -> None:
        self.recorder.publish(change.t, "/mission/state", {
            "state": change.dest, "from": change.source, "trigger": change.trigger,
            "reason": change.reason})

    def sampled(self, run: MissionRun, now: float) -> None:
        w, a = run.world, run.autonomy
        self.recorder.publish(now, "/pose/true", self._pose(now, w.x, w.y, w.yaw))
        if a is None:
            return
        est = a.kit.tracker.estimate()
        if est is not None:
            self.recorder.publish(now, "/pose/estimated", self._pose(now, est.x, est.y, est.yaw))
        self.recorder.publish(now, "/mission/numbers", {
            "pose_confidence": a.kit.tracker.confidence, "bin_kg": a.context.bin_kg,
            "true_bin_kg": w.bin_kg, "delivered_kg": w.delivered_kg, "lift": w.lift_pos,
            "localization_losses": a.context.localization_losses})
        key = (len(a.kit.log["planned"]), len(a.context.rocks) + len(a.context.craters))
        if key != self._map_key:
            self._map_key = key
            self.recorder.publish(now, "/map", self._scene(now, run))

    def finished(self, run: MissionRun) -> None:
        if run.rig is not None:
            run.rig.perception.scans.remove_listener(self._scan)
        self.recorder.close()
        files = sorted(self._dir.glob("*.mcap"))
        if files:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(str(files[-1]), self.path)
        shutil.rmtree(self._dir, ignore_errors=True)

    # -- messages ---------------------------------------------------------------------------------
    def _stamp(self, t: float) -> dict[str, int]:
        tb = self.recorder.timebase
        ns = tb.ns(t) if tb is not None else 0
        sec, nsec = divmod(ns, 1_000_000_000)
        return {"sec": sec, "nsec": nsec}

    def _pose(self, t: float, x: float, y: float, yaw: float) -> dict[str, Any]:
        return {"timestamp": self._stamp(t), "frame_id": FRAME,
                "pose": {"position": {"x": x, "y": y, "z": 0.0},
                         "orientation": _yaw_quat(yaw)}}

    def _scan(self, record: ScanRecord) -> None:
        run = self._run
        if run is None or run.autonomy is None:
            return
        est = run.autonomy.kit.tracker.estimate()
        if est is None:
            return
        from ramp.autonomy.mount import rotation_zyx

        turn = np.asarray(rotation_zyx(record.roll, record.pitch, est.yaw))
        pos = turn @ np.asarray(record.lidar_position) + np.array([est.x, est.y, 0.0])
        rot = turn @ np.asarray(record.lidar_rotation)
        ranges = np.where(np.isfinite(record.ranges), record.ranges, 0.0)
        self.recorder.publish(record.t, "/lidar/scan", {
            "timestamp": self._stamp(record.t), "frame_id": FRAME,
            "pose": {"position": {"x": float(pos[0]), "y": float(pos[1]), "z": float(pos[2])},
                     "orientation": _matrix_quat(rot)},
            "start_angle": float(record.angles[0]), "end_angle": float(record.angles[-1]),
            "ranges": [round(float(r), 3) for r in ranges], "intensities": []})

    def _scene(self, t: float, run: MissionRun) -> dict[str, Any]:
        assert run.autonomy is not None
        a = run.autonomy
        stamp = self._stamp(t)
        ident = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": _yaw_quat(0.0)}

        def colour(r: float, g: float, b: float, alpha: float = 1.0) -> dict[str, float]:
            return {"r": r, "g": g, "b": b, "a": alpha}

        def line(points: list[tuple[float, float]], c: dict[str, float]) -> dict[str, Any]:
            return {"type": 0, "pose": ident, "thickness": 0.03, "scale_invariant": False,
                    "points": [{"x": x, "y": y, "z": 0.02} for x, y in points], "color": c,
                    "colors": [], "indices": []}

        w = run.world.describe()["arena"]
        length, width = w["length"], w["width"]  # type: ignore[index]
        walls = line([(0, 0), (length, 0), (length, width), (0, width), (0, 0)],
                     colour(0.2, 0.2, 0.2))
        cylinders = [{"pose": {"position": {"x": d.x, "y": d.y, "z": 0.05},
                               "orientation": _yaw_quat(0.0)},
                      "size": {"x": 2 * d.radius, "y": 2 * d.radius, "z": 0.1},
                      "bottom_scale": 1.0, "top_scale": 1.0,
                      "color": colour(0.9, 0.2, 0.1, 0.7) if d in a.context.rocks
                      else colour(0.1, 0.2, 0.8, 0.7)}
                     for d in (*a.context.rocks, *a.context.craters)]
        lines = [walls]
        if a.context.plan is not None:
            for leg in a.context.plan.legs:
                lines.append(line([(float(p[0]), float(p[1])) for p in leg.points],
                                  colour(0.1, 0.6, 0.1)))
        entity = {"timestamp": stamp, "frame_id": FRAME, "id": "mission", "lifetime":
                  {"sec": 0, "nsec": 0}, "frame_locked": False, "metadata": [],
                  "arrows": [], "cubes": [], "spheres": [], "cylinders": cylinders,
                  "lines": lines, "triangles": [], "texts": [], "models": []}
        return {"deletions": [], "entities": [entity]}
