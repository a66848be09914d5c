"""`AutonomyView`: what the autonomy knows, as Foxglove messages on any channel sink (SPEC 8).

The same messages go to a recording (`ramp sim mission --record`, through the flight
recorder) and to the live view (`ramp-autonomy --foxglove-port P`, through `FoxgloveLive`),
or to both through `tee`: the view only calls the sink's `add_channel(spec)` and
`publish(t, topic, payload)`, and stamps messages with the sink's `timebase` once started.
Everything here is the autonomy's own belief (its pose estimate, what it detected, what it
planned); the simulator's truth (`/pose/true`, `true_*` numbers) is added by the simulator.

| topic | schema | one message per |
|---|---|---|
| `/mission/state` | `ramp.MissionState` | state change: state, from, trigger, reason |
| `/pose/estimated` | `foxglove.PoseInFrame` | 0.1 s while the autonomy has a pose |
| `/mission/numbers` | `ramp.MissionNumbers` | 0.1 s: pose confidence, bin load, delivered, lift |
| `/lidar/scan` | `foxglove.LaserScan` | each scan the autonomy took, at the estimated pose |
| `/map` | `foxglove.SceneUpdate` | when the map changes: walls, detected obstacles, the plan |
| `/obstacles` | `ramp.Obstacles` | with `/map`: each detected obstacle with its `kind` |
| `/arena` | `ramp.Arena` | once: the arena's and the robot's dimensions |

Typed fields, not pictures: a viewer reads an obstacle's `kind`, the `localization` enum of
`/mission/state` and the arena's size from `/arena`, never a colour or a wording; the state
names in `ramp.MissionState`'s schema are the mission table's own (`enum`).

`/map` holds two entities: `mission` (the walls, then the plan's legs; the detected rocks and
craters as cylinders) and `arena` (the regions' borders and the collector, in the order its
metadata `lines` names, with the robot's footprint and the arena's size in its metadata), so
a viewer with no copy of the arena (the operator console) can draw it all.

Frame `arena` (SPEC 6.1) throughout. `/map` and `/mission/state` change seldom: a live view
keeps their last message for clients that connect later (`LATCHED`).

Fed by three calls, each cheap: `state_changed` (the mission's listener), `scan` (the
perception's scan listener) and `tick` (a 10 Hz scheduler task); `watch(autonomy)` wires the
first two to an `Autonomy`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ramp.autonomy import arena
from ramp.autonomy.mount import rotation_zyx
from ramp.recorder.schemas import ChannelSpec
from ramp.statemachine.mission import LOCALIZATION
from ramp.statemachine.table import STATES as MISSION_STATES
from ramp.statemachine.table import TRIGGERS

if TYPE_CHECKING:
    from ramp.autonomy.executive.autonomy import Autonomy
    from ramp.autonomy.perception.records import ScanRecord
    from ramp.autonomy.planning import Pose
    from ramp.statemachine import MissionContext, StateChange

FRAME = "arena"
VIEW_HZ = 10.0  # the pose and the numbers; state changes, scans and the map as they happen

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
#: The mission's states, as the machine's own table names them (never a copy).
STATE_NAMES = [spec.name for spec in MISSION_STATES]
MISSION_STATE = {"title": "ramp.MissionState", "type": "object",
                 "description": "The mission machine's state change (SPEC 6.3)",
                 "properties": {"state": {"type": "string", "enum": STATE_NAMES},
                                "from": {"type": "string", "enum": STATE_NAMES},
                                "trigger": {"type": "string", "enum": list(TRIGGERS)},
                                "reason": {"type": "string"},
                                "localization": {
                                    "type": "string", "enum": list(LOCALIZATION),
                                    "description": "none: no fix yet; ok; lost: a loss not "
                                                   "recovered from; relocalizing: after a "
                                                   "hand-back"}},
                 "required": ["state", "from", "trigger", "reason", "localization"]}
#: The arena's fixed dimensions (SPEC 6.1), for a viewer with no copy of them.
ARENA = {"title": "ramp.Arena", "type": "object",
         "description": "The arena and the robot's footprint, metres, frame arena",
         "properties": {k: {"type": "number", "exclusiveMinimum": 0} for k in (
             "length_m", "width_m", "robot_length_m", "robot_width_m")},
         "required": ["length_m", "width_m", "robot_length_m", "robot_width_m"]}
OBSTACLE_KINDS = ["rock", "crater"]
#: The obstacles the autonomy detected, each with its kind (the map's cylinders only colour
#: them).
OBSTACLES = {"title": "ramp.Obstacles", "type": "object",
             "description": "Detected obstacles, frame arena",
             "properties": {"obstacles": {"type": "array", "items": {
                 "type": "object", "title": "ramp.Obstacle",
                 "properties": {"kind": {"type": "string", "enum": OBSTACLE_KINDS},
                                "x": {"type": "number"}, "y": {"type": "number"},
                                "radius": {"type": "number", "minimum": 0}},
                 "required": ["kind", "x", "y", "radius"]}}},
             "required": ["obstacles"]}
#: The autonomy's numbers; a simulation adds the truth beside them (`true_*`).
MISSION_NUMBERS = {"title": "ramp.MissionNumbers", "type": "object",
                   "description": "What the mission believes and what is true, 10 Hz",
                   "properties": {k: {"type": ["number", "null"]} for k in (
                       "pose_confidence", "bin_kg", "true_bin_kg", "delivered_kg",
                       "true_delivered_kg", "lift", "true_lift", "localization_losses")}}

STATE = ChannelSpec("/mission/state", "ramp.MissionState", MISSION_STATE)
POSE_ESTIMATED = ChannelSpec("/pose/estimated", "foxglove.PoseInFrame", POSE_IN_FRAME)
NUMBERS = ChannelSpec("/mission/numbers", "ramp.MissionNumbers", MISSION_NUMBERS)
SCAN = ChannelSpec("/lidar/scan", "foxglove.LaserScan", LASER_SCAN)
MAP = ChannelSpec("/map", "foxglove.SceneUpdate", SCENE_UPDATE)
ARENA_CHANNEL = ChannelSpec("/arena", "ramp.Arena", ARENA)
OBSTACLES_CHANNEL = ChannelSpec("/obstacles", "ramp.Obstacles", OBSTACLES)
CHANNELS = (STATE, POSE_ESTIMATED, NUMBERS, SCAN, MAP, ARENA_CHANNEL, OBSTACLES_CHANNEL)
#: Topics a live view keeps the last message of, for a client that subscribes later.
LATCHED = (MAP.topic, STATE.topic, ARENA_CHANNEL.topic, OBSTACLES_CHANNEL.topic)


class ChannelSink(Protocol):
    """The flight recorder's publishing calls (`Recorder`, `FoxgloveLive`, `Tee`)."""

    def add_channel(self, spec: ChannelSpec) -> None: ...

    def publish(self, t: float, topic: str, payload: Mapping[str, Any]) -> None: ...


class Tracker(Protocol):
    """What the view reads of the pose tracker (`executive.pose.PoseTracker`)."""

    @property
    def confidence(self) -> float: ...

    def estimate(self) -> Pose | None: ...


# -- message pieces -------------------------------------------------------------------------------
def stamp(timebase: Any, t: float) -> dict[str, int]:
    """A Foxglove time from the clock's seconds (`timebase.ns`; zero before a sink starts)."""
    ns = timebase.ns(t) if timebase is not None else 0
    sec, nsec = divmod(ns, 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def yaw_quat(yaw: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def matrix_quat(m: np.ndarray) -> dict[str, float]:
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


def pose_message(when: dict[str, int], x: float, y: float, yaw: float) -> dict[str, Any]:
    """A `foxglove.PoseInFrame` on the arena floor."""
    return {"timestamp": when, "frame_id": FRAME,
            "pose": {"position": {"x": x, "y": y, "z": 0.0}, "orientation": yaw_quat(yaw)}}


def _colour(r: float, g: float, b: float, alpha: float = 1.0) -> dict[str, float]:
    return {"r": r, "g": g, "b": b, "a": alpha}


_IDENTITY = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": yaw_quat(0.0)}
WALL_COLOUR = _colour(0.2, 0.2, 0.2)
ROCK_COLOUR = _colour(0.9, 0.2, 0.1, 0.7)
CRATER_COLOUR = _colour(0.1, 0.2, 0.8, 0.7)
PLAN_COLOUR = _colour(0.1, 0.6, 0.1)
REGION_COLOUR = _colour(0.5, 0.5, 0.5, 0.6)
COLLECTOR_COLOUR = _colour(0.9, 0.7, 0.1)
#: What each line of the `arena` entity is, in order (its metadata says it too).
ARENA_LINES = ("start_split", "start_end", "obstacle_end", "collector")


def _line(points: Sequence[tuple[float, float]], colour: dict[str, float]) -> dict[str, Any]:
    return {"type": 0, "pose": _IDENTITY, "thickness": 0.03, "scale_invariant": False,
            "points": [{"x": x, "y": y, "z": 0.02} for x, y in points], "color": colour,
            "colors": [], "indices": []}


def scene_message(when: dict[str, int], context: MissionContext) -> dict[str, Any]:
    """The map as a `foxglove.SceneUpdate`: the arena's walls (`ramp.autonomy.arena`), the
    rocks and craters detected, and the legs of the plan being driven."""
    length, width = arena.ARENA_LENGTH_M, arena.ARENA_WIDTH_M
    lines = [_line([(0, 0), (length, 0), (length, width), (0, width), (0, 0)], WALL_COLOUR)]
    cylinders = [{"pose": {"position": {"x": d.x, "y": d.y, "z": 0.05},
                           "orientation": yaw_quat(0.0)},
                  "size": {"x": 2 * d.radius, "y": 2 * d.radius, "z": 0.1},
                  "bottom_scale": 1.0, "top_scale": 1.0, "color": colour}
                 for discs, colour in ((context.rocks, ROCK_COLOUR),
                                       (context.craters, CRATER_COLOUR))
                 for d in discs]
    if context.plan is not None:
        for leg in context.plan.legs:
            lines.append(_line([(float(p[0]), float(p[1])) for p in leg.points], PLAN_COLOUR))
    entity = _entity(when, "mission", lines, cylinders)
    return {"deletions": [], "entities": [entity, arena_entity(when)]}


def _entity(when: dict[str, int], name: str, lines: list[dict[str, Any]],
            cylinders: list[dict[str, Any]], metadata: Sequence[tuple[str, str]] = ()
            ) -> dict[str, Any]:
    return {"timestamp": when, "frame_id": FRAME, "id": name,
            "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": False,
            "metadata": [{"key": k, "value": v} for k, v in metadata],
            "arrows": [], "cubes": [], "spheres": [], "cylinders": cylinders,
            "lines": lines, "triangles": [], "texts": [], "models": []}


def arena_entity(when: dict[str, int]) -> dict[str, Any]:
    """The arena's fixed parts (SPEC 6.1) for a viewer that has no copy of them (the
    console): the regions' borders, the collector behind the x = 0 wall, and in the metadata
    the robot's footprint and what each line is (`ARENA_LINES`)."""
    width = arena.ARENA_WIDTH_M
    half = arena.COLLECTOR_WIDTH_M / 2
    lines = [
        _line([(0.0, arena.START_SPLIT_Y_M), (arena.START_END_X_M, arena.START_SPLIT_Y_M)],
              REGION_COLOUR),
        _line([(arena.START_END_X_M, 0.0), (arena.START_END_X_M, width)], REGION_COLOUR),
        _line([(arena.OBSTACLE_END_X_M, 0.0), (arena.OBSTACLE_END_X_M, width)],
              REGION_COLOUR),
        _line([(0.0, arena.COLLECTOR_Y_M - half), (-0.25, arena.COLLECTOR_Y_M - half),
               (-0.25, arena.COLLECTOR_Y_M + half), (0.0, arena.COLLECTOR_Y_M + half)],
              COLLECTOR_COLOUR),
    ]
    meta = (("lines", ",".join(ARENA_LINES)), ("robot_length", str(arena.ROBOT_LENGTH_M)),
            ("robot_width", str(arena.ROBOT_WIDTH_M)),
            ("arena_length", str(arena.ARENA_LENGTH_M)), ("arena_width", str(width)))
    return _entity(when, "arena", lines, [], meta)


def arena_message() -> dict[str, float]:
    """`ramp.Arena`: the arena's and the robot's sizes (`ramp.autonomy.arena`)."""
    return {"length_m": arena.ARENA_LENGTH_M, "width_m": arena.ARENA_WIDTH_M,
            "robot_length_m": arena.ROBOT_LENGTH_M, "robot_width_m": arena.ROBOT_WIDTH_M}


def obstacles_message(context: MissionContext) -> dict[str, Any]:
    """`ramp.Obstacles`: every detected rock and crater with its kind."""
    return {"obstacles": [{"kind": kind, "x": round(d.x, 3), "y": round(d.y, 3),
                           "radius": round(d.radius, 3)}
                          for kind, discs in (("rock", context.rocks),
                                              ("crater", context.craters))
                          for d in discs]}


def scan_message(when: dict[str, int], record: ScanRecord, pose: Pose) -> dict[str, Any]:
    """A scan as a `foxglove.LaserScan` placed in the arena at the estimated pose (with the
    chassis' roll and pitch the AHRS gave it): what the autonomy believes it saw."""
    turn = np.asarray(rotation_zyx(record.roll, record.pitch, pose.yaw))
    pos = turn @ np.asarray(record.lidar_position) + np.array([pose.x, pose.y, 0.0])
    rot = turn @ np.asarray(record.lidar_rotation)
    ranges = np.where(np.isfinite(record.ranges), record.ranges, 0.0)
    return {"timestamp": when, "frame_id": FRAME,
            "pose": {"position": {"x": float(pos[0]), "y": float(pos[1]), "z": float(pos[2])},
                     "orientation": matrix_quat(rot)},
            "start_angle": float(record.angles[0]), "end_angle": float(record.angles[-1]),
            "ranges": [round(float(r), 3) for r in ranges], "intensities": []}


# -- the view -------------------------------------------------------------------------------------
class AutonomyView:
    """Publishes the autonomy's view (see the module docstring) on `sink`.

    `tracker` and `context`: the executive's pose tracker and the mission's context.
    `planned`: the plans made so far (`Kit.log["planned"]`; a new one redraws the map).
    `lift`: the lift position the backend last reported (NaN before any).
    """

    def __init__(self, sink: ChannelSink, tracker: Tracker, context: MissionContext, *,
                 planned: Sequence[object] = (),
                 lift: Callable[[], float] | None = None) -> None:
        self.sink = sink
        self.tracker = tracker
        self.context = context
        self.planned = planned
        self.lift = lift
        self.active = True
        self._map_key: tuple[int, int] = (-1, -1)
        self._arena_sent = False
        self._unwatch: Callable[[], None] | None = None
        for spec in CHANNELS:
            sink.add_channel(spec)

    @classmethod
    def watching(cls, sink: ChannelSink, autonomy: Autonomy) -> AutonomyView:
        """A view of `autonomy`, fed by its mission's state changes and its perception's
        scans; the caller runs `tick` at `VIEW_HZ` (a scheduler task) and `close`s it."""
        robot = autonomy.robot
        view = cls(sink, autonomy.kit.tracker, autonomy.context,
                   planned=autonomy.kit.log["planned"], lift=lambda: robot.lift_pos)
        scans = autonomy.kit.perception.scans
        autonomy.mission.add_listener(view.state_changed)
        scans.add_listener(view.scan)
        view._unwatch = lambda: scans.remove_listener(view.scan)
        return view

    def close(self) -> None:
        """Publish nothing more (the mission keeps its listener; it is a no-op now)."""
        self.active = False
        if self._unwatch is not None:
            self._unwatch()
            self._unwatch = None

    # -- the feeds -------------------------------------------------------------------------------
    def state_changed(self, change: StateChange) -> None:
        """The mission's listener: one `/mission/state` message."""
        if self.active:
            self.sink.publish(change.t, STATE.topic, {
                "state": change.dest, "from": change.source, "trigger": change.trigger,
                "reason": change.reason, "localization": change.localization or "none"})

    def tick(self, now: float, dt: float) -> None:
        """Scheduler task at `VIEW_HZ`."""
        self.sample(now)

    def sample(self, now: float, truth: Mapping[str, Any] | None = None) -> None:
        """`/pose/estimated` (while there is a pose), `/mission/numbers` (with `truth`'s
        fields beside the autonomy's, in a simulation) and `/map` when it changed."""
        if not self.active:
            return
        when = self._stamp(now)
        est = self.tracker.estimate()
        if est is not None:
            self.sink.publish(now, POSE_ESTIMATED.topic, pose_message(when, est.x, est.y,
                                                                      est.yaw))
        ctx = self.context
        numbers: dict[str, Any] = {
            "pose_confidence": self.tracker.confidence, "bin_kg": ctx.bin_kg,
            "delivered_kg": ctx.delivered_kg,
            "lift": self.lift() if self.lift is not None else None,
            "localization_losses": ctx.localization_losses}
        if truth:
            numbers.update(truth)
        self.sink.publish(now, NUMBERS.topic, numbers)
        if not self._arena_sent:
            self._arena_sent = True
            self.sink.publish(now, ARENA_CHANNEL.topic, arena_message())
        key = (len(self.planned), len(ctx.rocks) + len(ctx.craters))
        if key != self._map_key:
            self._map_key = key
            self.sink.publish(now, MAP.topic, scene_message(when, ctx))
            self.sink.publish(now, OBSTACLES_CHANNEL.topic, obstacles_message(ctx))

    def scan(self, record: ScanRecord) -> None:
        """The perception's scan listener: the scan at the pose estimated now (none while
        the autonomy has no pose: it could not say where the scan was taken)."""
        if not self.active or not self._wanted(SCAN.topic):
            return
        est = self.tracker.estimate()
        if est is not None:
            self.sink.publish(record.t, SCAN.topic,
                              scan_message(self._stamp(record.t), record, est))

    # -- inside -------------------------------------------------------------------------------
    def _stamp(self, t: float) -> dict[str, int]:
        return stamp(getattr(self.sink, "timebase", None), t)

    def _wanted(self, topic: str) -> bool:
        """Whether the sink takes `topic` now (a live view nobody watches does not), so a
        scan's thousand ranges are not formatted for nobody. Sinks that cannot say take
        everything."""
        wants = getattr(self.sink, "wants", None)
        return True if wants is None else bool(wants(topic))
