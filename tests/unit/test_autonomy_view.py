"""The autonomy's view (`ramp.autonomy.live.view.AutonomyView`) on a fake channel sink: what it
declares, what it publishes from the pose tracker, the mission's context, state changes and
scans, when the map is redrawn, and that every message is valid against its channel's JSON
Schema. The same view feeds `ramp sim mission --record` and `ramp-autonomy --foxglove-port`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import jsonschema
import numpy as np
import pytest

from ramp.autonomy import arena
from ramp.autonomy.executive.pose import PoseTracker
from ramp.autonomy.live.view import CHANNELS, LATCHED, AutonomyView
from ramp.autonomy.odometry import Odometry
from ramp.autonomy.perception.records import ScanRecord
from ramp.autonomy.planning import Disc, Path, PlanResult
from ramp.recorder.schemas import ChannelSpec
from ramp.recorder.writer import TimeBase
from ramp.statemachine import MissionContext, StateChange
from ramp.statemachine.mission import LOCALIZATION
from ramp.statemachine.table import STATES

ORIGIN = 1_779_285_600_000_000_000  # 2026-05-20 14:00:00 UTC at clock time 10 s


class FakeSink:
    """Takes what a recorder or live view takes; `watched` plays a live view's `wants`."""

    def __init__(self) -> None:
        self.specs: dict[str, ChannelSpec] = {}
        self.messages: list[tuple[float, str, dict[str, Any]]] = []
        self.timebase = TimeBase(10.0, ORIGIN)
        self.watched = {spec.topic for spec in CHANNELS}

    def add_channel(self, spec: ChannelSpec) -> None:
        self.specs[spec.topic] = spec

    def publish(self, t: float, topic: str, payload: Mapping[str, Any]) -> None:
        assert topic in self.specs, f"{topic} published before it was declared"
        jsonschema.validate(dict(payload), self.specs[topic].schema)
        self.messages.append((t, topic, dict(payload)))

    def wants(self, topic: str) -> bool:
        return topic in self.watched

    def on(self, topic: str) -> list[dict[str, Any]]:
        return [p for _, t, p in self.messages if t == topic]


def make_view(**kw: Any) -> tuple[AutonomyView, FakeSink, PoseTracker, MissionContext]:
    sink = FakeSink()
    tracker = PoseTracker(Odometry(), None)
    ctx = MissionContext()
    tracker.bind(ctx)
    return AutonomyView(sink, tracker, ctx, **kw), sink, tracker, ctx


def test_the_view_declares_its_channels_in_foxglove_schemas_where_foxglove_has_one(
        ) -> None:
    _, sink, _, _ = make_view()
    assert {t: s.schema_name for t, s in sink.specs.items()} == {
        "/mission/state": "ramp.MissionState", "/pose/estimated": "foxglove.PoseInFrame",
        "/mission/numbers": "ramp.MissionNumbers", "/lidar/scan": "foxglove.LaserScan",
        "/map": "foxglove.SceneUpdate", "/arena": "ramp.Arena",
        "/obstacles": "ramp.Obstacles"}
    for spec in sink.specs.values():
        jsonschema.Draft202012Validator.check_schema(spec.schema)
    assert set(LATCHED) == {"/map", "/mission/state", "/arena", "/obstacles"}


def test_the_state_schema_names_the_machine_s_own_states_and_localization_enum() -> None:
    """Issue 35: the console kept its own copy of the recovery states' names."""
    _, sink, _, _ = make_view()
    props = sink.specs["/mission/state"].schema["properties"]
    assert props["state"]["enum"] == [s.name for s in STATES]
    assert props["localization"]["enum"] == list(LOCALIZATION)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"state": "no_such_state", "from": "idle", "trigger": "start",
                             "reason": "", "localization": "ok"},
                            sink.specs["/mission/state"].schema)


def test_obstacles_carry_their_kind_and_the_arena_its_size_as_typed_fields() -> None:
    view, sink, _, ctx = make_view()
    ctx.rocks.append(Disc(3.0, 1.0, 0.15))
    ctx.craters.append(Disc(2.5, 3.0, 0.1))
    view.tick(10.0, 0.1)
    view.tick(10.1, 0.1)
    (arena_msg,) = sink.on("/arena")  # once: it never changes
    assert arena_msg == {"length_m": arena.ARENA_LENGTH_M, "width_m": arena.ARENA_WIDTH_M,
                         "robot_length_m": arena.ROBOT_LENGTH_M,
                         "robot_width_m": arena.ROBOT_WIDTH_M}
    (obstacles,) = sink.on("/obstacles")
    assert obstacles == {"obstacles": [
        {"kind": "rock", "x": 3.0, "y": 1.0, "radius": 0.15},
        {"kind": "crater", "x": 2.5, "y": 3.0, "radius": 0.1}]}


def test_before_a_fix_it_sends_numbers_and_the_walls_but_no_pose() -> None:
    view, sink, _, ctx = make_view(lift=lambda: math.nan)
    ctx.bin_kg, ctx.delivered_kg, ctx.localization_losses = 2.5, 7.0, 1
    view.tick(11.0, 0.1)
    assert sink.on("/pose/estimated") == []
    (numbers,) = sink.on("/mission/numbers")
    assert math.isnan(numbers.pop("lift"))  # none reported yet: null on the wire
    assert numbers == {"pose_confidence": 0.0, "bin_kg": 2.5, "delivered_kg": 7.0,
                       "localization_losses": 1}
    (scene,) = sink.on("/map")
    entity = scene["entities"][0]
    assert entity["frame_id"] == "arena" and entity["cylinders"] == []
    (walls,) = entity["lines"]
    corners = [(p["x"], p["y"]) for p in walls["points"]]
    assert corners == [(0, 0), (arena.ARENA_LENGTH_M, 0),
                       (arena.ARENA_LENGTH_M, arena.ARENA_WIDTH_M), (0, arena.ARENA_WIDTH_M),
                       (0, 0)]
    assert entity["timestamp"] == {"sec": ORIGIN // 10**9 + 1, "nsec": 0}


def test_with_a_fix_it_sends_the_estimated_pose_at_10_hz_and_the_map_only_when_it_changes(
        ) -> None:
    view, sink, tracker, ctx = make_view()
    tracker.fix(10.0, 2.0, 1.5, math.pi / 2, 0.8)
    for i in range(5):
        view.tick(10.0 + 0.1 * i, 0.1)
    poses = sink.on("/pose/estimated")
    assert len(poses) == 5 and len(sink.on("/mission/numbers")) == 5
    assert poses[0]["pose"]["position"] == {"x": 2.0, "y": 1.5, "z": 0.0}
    q = poses[0]["pose"]["orientation"]
    assert (q["z"], q["w"]) == pytest.approx((math.sin(math.pi / 4), math.cos(math.pi / 4)))
    assert [m[0] for m in sink.messages if m[1] == "/pose/estimated"] == pytest.approx(
        [10.0, 10.1, 10.2, 10.3, 10.4])
    assert sink.on("/mission/numbers")[0]["pose_confidence"] == pytest.approx(0.8)
    assert len(sink.on("/map")) == 1  # nothing new detected or planned

    ctx.rocks.append(Disc(3.0, 1.0, 0.15))
    ctx.craters.append(Disc(2.5, 3.0, 0.1))
    view.tick(10.5, 0.1)
    cylinders = sink.on("/map")[-1]["entities"][0]["cylinders"]
    assert [(c["pose"]["position"]["x"], c["size"]["x"]) for c in cylinders] == [
        (3.0, 0.3), (2.5, 0.2)]
    assert cylinders[0]["color"] != cylinders[1]["color"]  # rocks and craters apart

    planned: list[object] = []
    view.planned = planned
    ctx.plan = PlanResult((Path(np.array([[0.8, 1.9], [2.0, 2.0], [3.9, 2.0]])),))
    planned.append(ctx.plan)
    view.tick(10.6, 0.1)
    view.tick(10.7, 0.1)
    assert len(sink.on("/map")) == 3
    lines = sink.on("/map")[-1]["entities"][0]["lines"]
    assert [(p["x"], p["y"]) for p in lines[1]["points"]] == [(0.8, 1.9), (2.0, 2.0),
                                                              (3.9, 2.0)]


def test_a_state_change_is_one_message_with_where_it_came_from_and_why() -> None:
    view, sink, _, _ = make_view()
    view.state_changed(StateChange(12.5, "dock", "deposit", "finished", "docked at x 0.62",
                                   "ok"))
    assert sink.messages == [(12.5, "/mission/state", {
        "state": "deposit", "from": "dock", "trigger": "finished",
        "reason": "docked at x 0.62", "localization": "ok"})]


def _scan(t: float) -> ScanRecord:
    angles = np.radians(np.linspace(-135.0, 135.0, 1081))
    ranges = np.full(1081, 2.0)
    ranges[:10] = np.nan  # nothing usable: 0 on the wire (Foxglove draws nothing there)
    return ScanRecord(t, ranges, angles, (0.4, 0.0, 0.7), np.eye(3), 0.0, 0.0)


def test_a_scan_is_placed_at_the_estimated_pose_and_none_is_sent_without_one() -> None:
    view, sink, tracker, _ = make_view()
    view.scan(_scan(10.0))
    assert sink.on("/lidar/scan") == []  # no pose: no idea where it was taken
    tracker.fix(10.0, 2.0, 1.0, math.pi / 2, 1.0)
    view.scan(_scan(10.025))
    (scan,) = sink.on("/lidar/scan")
    assert scan["pose"]["position"] == pytest.approx({"x": 2.0, "y": 1.4, "z": 0.7})
    q = scan["pose"]["orientation"]
    assert (q["x"], q["y"], q["z"], q["w"]) == pytest.approx(
        (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)))
    assert scan["start_angle"] == pytest.approx(-0.75 * math.pi)
    assert scan["ranges"][:10] == [0.0] * 10 and scan["ranges"][10] == 2.0
    assert scan["timestamp"] == {"sec": ORIGIN // 10**9, "nsec": 25_000_000}


def test_a_scan_nobody_watches_is_not_built_and_a_closed_view_sends_nothing() -> None:
    view, sink, tracker, _ = make_view()
    tracker.fix(10.0, 2.0, 1.0, 0.0, 1.0)
    sink.watched.discard("/lidar/scan")
    view.scan(_scan(10.0))
    assert sink.on("/lidar/scan") == []
    view.close()
    view.tick(10.1, 0.1)
    view.state_changed(StateChange(10.2, "a", "b", "t", ""))
    assert sink.messages == []


def test_a_simulation_adds_the_truth_beside_the_autonomy_numbers() -> None:
    view, sink, _, _ = make_view(lift=lambda: 0.25)
    view.sample(10.0, truth={"true_bin_kg": 3.0, "true_delivered_kg": 1.0, "true_lift": 0.3})
    (numbers,) = sink.on("/mission/numbers")
    assert numbers["lift"] == 0.25
    assert (numbers["true_bin_kg"], numbers["true_delivered_kg"], numbers["true_lift"]) == (
        3.0, 1.0, 0.3)
