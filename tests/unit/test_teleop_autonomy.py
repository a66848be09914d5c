"""The console's client of the autonomy's live view, against a real `FoxgloveLive` on loopback:
it takes only what the page draws, at the rate it draws it, and reads the view's messages
(state, numbers, poses, the map's arena, obstacles and plan, a scan placed in the arena)."""

from __future__ import annotations

import asyncio
import math
from collections import Counter

from ramp.autonomy.live import FoxgloveLive
from ramp.autonomy.live.view import (
    CHANNELS,
    LATCHED,
    arena_entity,
    pose_message,
    yaw_quat,
)
from ramp.recorder.schemas import ChannelSpec
from ramp.teleop.autonomy import AutonomyLink, map_view, scan_points

ORIGIN = 1_779_285_600_000_000_000
WHEN = {"sec": 1, "nsec": 0}


def test_a_scan_is_placed_in_the_arena_at_its_pose_and_thinned() -> None:
    scan = {"pose": {"position": {"x": 1.0, "y": 2.0, "z": 0.5},
                     "orientation": yaw_quat(math.pi / 2)},
            "start_angle": -math.pi / 2, "end_angle": math.pi / 2,
            "ranges": [1.0, 0.0, 2.0] + [1.0] * 997}
    points = scan_points(scan, limit=100)
    assert len(points) <= 100
    assert points[0] == (2.0, 2.0)  # -90 deg of a sensor facing +y points along +x
    assert all(abs(math.hypot(x - 1.0, y - 2.0) - 1.0) < 0.02 or abs(
        math.hypot(x - 1.0, y - 2.0) - 2.0) < 0.02 for x, y in points)


def test_the_map_gives_walls_regions_collector_obstacles_plan_and_footprint() -> None:
    red, blue = {"r": 0.9, "g": 0.2, "b": 0.1, "a": 1}, {"r": 0.1, "g": 0.2, "b": 0.8, "a": 1}

    def line(*pts: tuple[float, float]) -> dict[str, object]:
        return {"points": [{"x": x, "y": y, "z": 0} for x, y in pts]}

    def disc(x: float, y: float, r: float, colour: dict[str, float]) -> dict[str, object]:
        return {"pose": {"position": {"x": x, "y": y, "z": 0}}, "size": {"x": 2 * r},
                "color": colour}

    scene = {"entities": [
        {"id": "mission", "lines": [line((0, 0), (7.38, 0)), line((1, 1), (2, 1))],
         "cylinders": [disc(3, 1, 0.15, red), disc(2.5, 3, 0.1, blue)]},
        arena_entity(WHEN)]}
    m = map_view(scene)
    assert m["walls"] == [(0, 0), (7.38, 0)] and m["plan"] == [[(1, 1), (2, 1)]]
    assert len(m["regions"]) == 3 and len(m["collector"]) == 1
    assert m["robot"] == [1.2, 0.75]


def test_obstacles_and_the_arena_s_size_are_read_from_typed_fields_not_colours() -> None:
    """Issue 35: a rock was told from a crater by its colour; now by `kind` (`/obstacles`),
    and the arena's size is the view's `/arena`, not a constant in the page."""
    link = AutonomyLink("127.0.0.1", 9)
    link._take("/obstacles", {"obstacles": [
        {"kind": "crater", "x": 3, "y": 1, "radius": 0.15},
        {"kind": "rock", "x": 2.5, "y": 3, "radius": 0.1}]}, 0, 0.0)
    link._take("/arena", {"length_m": 9.0, "width_m": 5.0, "robot_length_m": 1.0,
                          "robot_width_m": 0.5}, 0, 0.0)
    # A later map keeps what the typed channels said.
    link._take("/map", {"entities": [arena_entity(WHEN)]}, 0, 0.0)
    m = link.view.map
    assert m["obstacles"] == [{"kind": "crater", "x": 3.0, "y": 1.0, "radius": 0.15},
                              {"kind": "rock", "x": 2.5, "y": 3.0, "radius": 0.1}]
    assert m["arena"] == {"length_m": 9.0, "width_m": 5.0, "robot_length_m": 1.0,
                          "robot_width_m": 0.5}
    assert m["robot"] == [1.0, 0.5]


def test_it_takes_poses_at_its_own_rate_and_state_and_map_as_they_change() -> None:
    live = FoxgloveLive(origin_ns=ORIGIN, latched=LATCHED)
    for spec in CHANNELS:
        live.add_channel(spec)
    live.add_channel(ChannelSpec("/pose/true", "foxglove.PoseInFrame", CHANNELS[1].schema))
    port = live.start(0.0)
    got: Counter[str] = Counter()

    async def run() -> AutonomyLink:
        link = AutonomyLink("127.0.0.1", port, on_update=lambda kind: got.update([kind]),
                            pose_period=0.5, scan_period=2.0, retry=0.1)
        task = asyncio.create_task(link.run())
        for _ in range(100):
            if live.subscriptions >= 2:
                break
            await asyncio.sleep(0.02)
        live.publish(0.0, "/mission/state", {"state": "cross_to_dig", "from": "plan_path_to_dig",
                                              "trigger": "finished", "reason": "go"})
        live.publish(0.0, "/map", {"deletions": [], "entities": [arena_entity(WHEN)]})
        for i in range(20):  # 2 s of a 10 Hz view
            t = 0.1 * i
            live.publish(t, "/pose/estimated", pose_message(WHEN, 1.0 + t, 2.0, 0.5))
            live.publish(t, "/pose/true", pose_message(WHEN, 1.0 + t, 2.01, 0.5))
            live.publish(t, "/mission/numbers", {"pose_confidence": 0.9, "bin_kg": 3.0})
            await asyncio.sleep(0.1)
        await link.close()
        task.cancel()
        return link

    try:
        link = asyncio.run(run())
    finally:
        live.close()
    v = link.view
    assert v.state == "cross_to_dig" and v.reason == "go"
    assert v.numbers == {"pose_confidence": 0.9, "bin_kg": 3.0}
    assert v.pose is not None and v.true_pose is not None and v.pose[1] == 2.0
    assert v.map["robot"] == [1.2, 0.75] and v.map_version == 1
    # 2 s at one every 0.5 s: about 4 of the 20 published, never all.
    assert 2 <= got["/pose/estimated"] <= 6, got
    assert 2 <= got["/mission/numbers"] <= 6, got
    assert got["/mission/state"] == 1 and got["/map"] == 1
    assert link.bytes_in > 0 and link.bytes_out > 0


def test_localization_is_the_view_s_enum_not_a_reading_of_names_or_reasons() -> None:
    link = AutonomyLink("127.0.0.1", 9)
    for state, reason, localization in (
            ("relevel", "control acquired as autonomy", "relocalizing"),
            ("stop", "lost: too few returns to localize", "lost"),
            ("cross_to_dig", "lost count 3 is fine", "ok")):
        link._take("/mission/state", {"state": state, "from": "", "trigger": "finished",
                                      "reason": reason, "localization": localization}, 0, 0.0)
        assert link.view.localization == localization, state
        assert link.view.summary(0.0)["localization"] == localization
