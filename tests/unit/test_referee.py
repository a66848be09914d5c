"""The trace referee on hand-made traces: touching, near misses, docking, a corner clipping a
rock while turning, fast passes between samples, deliveries away from the collector."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from ramp.simulation.referee import RefereeRules, TraceError, read_trace, referee

ROCK = {"x": 3.0, "y": 2.0, "d": 0.2}  # radius 0.1
CRATER = {"x": 5.0, "y": 1.0, "d": 0.3, "depth": 0.2}


def header(rocks: list[dict[str, float]] | None = None,
           craters: list[dict[str, float]] | None = None) -> dict[str, Any]:
    return {"arena": {"length": 7.38, "width": 3.88, "collector_y": 1.94,
                      "collector_width": 1.65},
            "robot": {"length": 1.2, "width": 0.75},
            "rocks": [ROCK] if rocks is None else rocks,
            "craters": [CRATER] if craters is None else craters,
            "start": {"box": "left", "heading": 0, "x": 0.75, "y": 2.9, "yaw": 0.0},
            "seed": 1, "fault": "none"}


def sample(t: float, x: float, y: float, yaw: float, delivered: float = 0.0,
           state: str = "cross") -> dict[str, Any]:
    return {"t": round(t, 3), "x": x, "y": y, "yaw": yaw, "lift": 0.0, "bin_kg": 0.0,
            "delivered_kg": delivered, "state": state}


def lines(poses: list[tuple[float, ...]], head: dict[str, Any] | None = None) -> list[str]:
    """A trace with one sample per 0.1 s at the given (x, y, yaw deg[, delivered]) poses."""
    rows = [sample(0.1 * k, *p) for k, p in enumerate(poses)]
    return [json.dumps(head or header())] + [json.dumps(r) for r in rows]


def drive(x0: float, x1: float, y: float, n: int, yaw: float = 0.0) -> list[tuple[float, ...]]:
    return [(x0 + (x1 - x0) * k / (n - 1), y, yaw) for k in range(n)]


def test_a_front_edge_touching_a_rock_is_one_collision_however_long_it_lasts() -> None:
    # Front edge at x + 0.6; the rock's near edge at 2.9. Stops 5 mm into it, stays 1 s.
    poses = drive(1.0, 2.305, 2.0, 20) + [(2.305, 2.0, 0.0)] * 10
    report = referee(lines(poses))
    assert report.collisions == 1 and report.crater_entries == 0
    event = report.events[0]
    assert (event.kind, event.what) == ("collision", "rock 0")
    assert event.depth_m == pytest.approx(0.005, abs=1e-6)
    assert event.t_end == pytest.approx(2.9)


def test_exact_contact_with_a_rock_counts_and_a_millimetre_gap_does_not() -> None:
    touching = referee(lines(drive(1.0, 2.3, 2.0, 14)))
    assert touching.collisions == 1
    near_miss = referee(lines(drive(1.0, 2.299, 2.0, 14)))
    assert near_miss.collisions == 0


def test_passing_beside_a_rock_with_a_centimetre_to_spare_is_no_collision() -> None:
    # Side edge at y + 0.375; the rock's lower edge at 1.9: pass 1 cm below it.
    report = referee(lines(drive(1.0, 5.0, 1.9 - 0.375 - 0.01, 40), header(craters=[])))
    assert report.collisions == 0 and report.events == ()


def test_a_pass_faster_than_the_samples_is_still_caught() -> None:
    # 3 m in one 0.1 s step, straight through the rock: neither sample overlaps it.
    poses = [(1.5, 2.0, 0.0), (4.5, 2.0, 0.0), (4.6, 2.0, 0.0)]
    report = referee(lines(poses))
    assert report.collisions == 1 and report.events[0].what == "rock 0"
    coarse = referee(lines(poses), RefereeRules(substep_m=10.0))  # no sub-sampling
    assert coarse.collisions == 0


def test_a_corner_clipping_a_rock_while_turning_in_place_is_a_collision() -> None:
    # A small rock 0.70 m out at 77 deg: clear of the rectangle at yaw 0 (0.27 m beside it)
    # and at yaw 90 (0.04 m ahead of it), but the front-left corner, 0.71 m out at 32 deg,
    # sweeps through it while the robot spins from one sample to the next.
    rx, ry = 2.0 + 0.7 * math.cos(math.radians(77)), 2.0 + 0.7 * math.sin(math.radians(77))
    head = header(rocks=[{"x": rx, "y": ry, "d": 0.08}], craters=[])
    poses = [(2.0, 2.0, 0.0), (2.0, 2.0, 0.0), (2.0, 2.0, 90.0), (2.0, 2.0, 90.0)]
    still = [[p] * 3 for p in poses[::3]]
    assert referee(lines(still[0], head)).collisions == 0  # neither end pose overlaps
    assert referee(lines(still[1], head)).collisions == 0
    report = referee(lines(poses, head))
    assert report.collisions == 1
    assert 30.0 < report.events[0].yaw_deg < 60.0


def test_crater_entries_count_each_entry_once() -> None:
    # Drive over the crater, back off, drive over it again.
    there = drive(3.5, 4.9, 1.0, 15)
    back = drive(4.9, 3.5, 1.0, 15)
    report = referee(lines(there + back + there))
    assert report.crater_entries == 2 and report.collisions == 0
    assert {e.what for e in report.events} == {"crater 0"}


def test_docking_with_the_rear_at_the_collector_is_not_a_collision() -> None:
    # Back onto the x = 0 wall, rear centred on the collector, then dump 12 kg.
    approach = drive(1.8, 0.6, 1.94, 13)
    dump = [(0.6, 1.94, 0.0, 0.5 * k) for k in range(25)]
    report = referee(lines(approach + dump))
    assert report.collisions == 0 and report.dock_contacts == 1
    assert report.delivered_at_collector_kg == pytest.approx(12.0)
    assert report.delivered_elsewhere_kg == 0.0
    assert report.qualifies


def test_docking_slightly_skewed_still_counts_as_docking() -> None:
    # 2 deg off square: one rear corner on the wall, the other 2.6 cm off it.
    yaw = 2.0
    x = 0.6 * math.cos(math.radians(yaw)) + 0.375 * math.sin(math.radians(yaw))
    report = referee(lines(drive(1.5, x, 1.94, 10, yaw)))
    assert report.collisions == 0 and report.dock_contacts == 1


@pytest.mark.parametrize(("pose", "why"), [
    ((0.6, 0.6, 0.0), "outside the collector's width"),
    ((0.375, 1.94, 90.0), "side against the wall"),
    ((0.6, 1.94, 180.0), "front against the wall"),
    ((0.57, 1.94, 0.0), "3 cm into the wall"),
])
def test_touching_the_collector_wall_any_other_way_is_a_collision(
        pose: tuple[float, float, float], why: str) -> None:
    x, y, yaw = pose
    report = referee(lines([(x + 1.0, y, yaw), (x + 0.5, y, yaw), (x, y, yaw), (x, y, yaw)]))
    assert report.collisions == 1, why
    assert report.events[0].what == "wall x=0"


def test_touching_a_side_wall_is_a_collision() -> None:
    report = referee(lines(drive(2.0, 6.0, 3.88 - 0.375, 20)))
    assert report.collisions == 1 and report.events[0].what == "wall y=3.88"


def test_a_delivery_away_from_the_collector_is_flagged_and_not_counted() -> None:
    poses = [(3.0, 3.2, 0.0, 0.0)] + [(3.0, 3.2, 0.0, 1.0 * k) for k in range(1, 13)]
    report = referee(lines(poses, header(rocks=[], craters=[])))
    assert report.delivered_kg == 12.0
    assert report.delivered_at_collector_kg == 0.0
    assert report.delivered_elsewhere_kg == pytest.approx(12.0)
    bad = [e for e in report.events if e.kind == "bad_delivery"]
    assert len(bad) == 1 and bad[0].kg == pytest.approx(12.0)
    assert not report.qualifies


def test_a_delivery_with_the_rear_0_2_m_off_the_wall_is_not_at_the_collector() -> None:
    poses = [(0.8, 1.94, 0.0, 0.5 * k) for k in range(30)]  # rear edge at x = 0.2
    report = referee(lines(poses, header(rocks=[], craters=[])))
    assert report.delivered_at_collector_kg == 0.0
    assert report.delivered_elsewhere_kg == pytest.approx(14.5)


def test_reads_a_trace_file_and_names_the_line_of_a_bad_sample(tmp_path: Path) -> None:
    good = tmp_path / "run.trace"
    good.write_text("\n".join(lines(drive(1.0, 2.0, 1.0, 5))) + "\n")
    trace = read_trace(good)
    assert len(trace.t) == 5 and trace.world.rocks[0].radius == 0.1
    assert referee(good).samples == 5
    bad = tmp_path / "bad.trace"
    text = lines(drive(1.0, 2.0, 1.0, 5))
    text[3] = text[3].replace('"x": ', '"x": "oops", "was": ')
    bad.write_text("\n".join(text))
    with pytest.raises(TraceError, match=r"bad\.trace:4: x: expected a number"):
        read_trace(bad)
    with pytest.raises(TraceError, match=r":2: not JSON"):
        read_trace([json.dumps(header()), "{not json"])
    with pytest.raises(TraceError, match="robot"):
        read_trace([json.dumps({"arena": {}}), json.dumps(sample(0, 1, 1, 0))])
