"""World files (SPEC 6.1 `--world FILE`): the examples load, mistakes name file:line:key."""

from __future__ import annotations

from pathlib import Path

import pytest

from firmware_like.arena import Crater, Rock, StartSpec, rule_problems
from firmware_like.world_file import WorldFileError, load_world, parse_world

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = sorted((REPO / "examples" / "worlds").glob("*.yaml"))

SPEC_EXAMPLE = """\
start: {box: left, heading: 90}              # optional x, y, yaw override the box's default
rocks:   [{x: 2.10, y: 0.90, d: 0.25}, {x: 3.30, y: 2.60, d: 0.12}, {x: 2.80, y: 1.70, d: 0.30}]
craters: [{x: 3.90, y: 1.10, d: 0.30, depth: 0.25}, {x: 2.40, y: 3.20, d: 0.20, depth: 0.15}]
"""


def errors(text: str, name: str = "w.yaml") -> list[str]:
    with pytest.raises(WorldFileError) as info:
        parse_world(text, name)
    return [str(e) for e in info.value.errors]


def test_the_spec_s_example_parses_to_its_layout() -> None:
    layout = parse_world(SPEC_EXAMPLE, "spec.yaml")
    assert layout.start == StartSpec("left", 90.0)
    assert layout.rocks[0] == Rock(2.10, 0.90, 0.25, pytest.approx(0.15))
    assert [r.d for r in layout.rocks] == [0.25, 0.12, 0.30]
    assert layout.craters == (Crater(3.90, 1.10, 0.30, 0.25), Crater(2.40, 3.20, 0.20, 0.15))
    assert layout.source == "spec.yaml"
    assert rule_problems(layout) == []


def test_there_are_three_example_worlds_and_each_loads() -> None:
    assert len(EXAMPLES) >= 3
    names = {p.name for p in EXAMPLES}
    assert "default.yaml" in names
    for path in EXAMPLES:
        layout = load_world(path)
        assert layout.rocks and layout.craters and layout.start is not None


def test_the_default_example_is_the_spec_s_layout() -> None:
    default = load_world(REPO / "examples" / "worlds" / "default.yaml")
    spec = parse_world(SPEC_EXAMPLE)
    assert (default.rocks, default.craters, default.start) == (spec.rocks, spec.craters,
                                                               spec.start)


def test_heights_depths_and_a_pinned_start_are_read() -> None:
    layout = parse_world("start: {box: right, heading: 270, x: 0.8, y: 0.9, yaw: -95.5}\n"
                         "rocks: [{x: 2, y: 1, d: 0.2, height: 0.17}]\n"
                         "craters:\n  - {x: 3, y: 2, d: 0.3}\n")
    assert layout.start == StartSpec("right", 270.0, 0.8, 0.9, -95.5)
    assert layout.rocks[0].height == 0.17
    assert layout.craters[0].depth == pytest.approx(0.15)  # half the diameter by default


def test_any_layout_inside_the_arena_is_accepted() -> None:
    layout = parse_world("rocks: [{x: 6.5, y: 3.0, d: 0.6}, {x: 5, y: 1, d: 0.05}]\n"
                         "craters: []\n")
    assert len(layout.rocks) == 2 and layout.start is None
    assert rule_problems(layout)  # it departs from the rules, and that is allowed
    assert parse_world("").rocks == ()


@pytest.mark.parametrize(("text", "expected"), [
    ("rocks:\n  - {x: 2.1, y: 0.9, d: big}\n",
     "w.yaml:2: rocks[0].d: expected a diameter in metres > 0, got the text 'big'"),
    ("rocks:\n  - {x: 2.1, y: 0.9}\n", "w.yaml:2: rocks[0].d: missing; expected a diameter"),
    ("rocks:\n  - {x: 2.1, y: 0.9, d: 0.2}\n  - {x: 2.5, y: 1, d: -0.2}\n",
     "w.yaml:3: rocks[1].d: expected a diameter in metres > 0, got -0.2"),
    ("craters:\n  - x: 3.0\n    y: 1.0\n    d: 0.3\n    depth: 0\n",
     "w.yaml:5: craters[0].depth: expected a depth in metres > 0, got 0"),
    # Sizes the ray caster cannot take (an overflow, then NaN ranges and no obstacle found).
    ("craters:\n  - {x: 3, y: 1, d: 1.0e-300, depth: 0.2}\n",
     "w.yaml:2: craters[0].d: expected a diameter of 0.01 m or more, got 1e-300"),
    ("craters:\n  - {x: 3, y: 1, d: 0.3, depth: 1.0e+308}\n",
     "w.yaml:2: craters[0].depth: expected at most 10 m, got 1e+308"),
    ("rocks:\n  - {x: 3, y: 1, d: 0.3}\n  - {x: 2, y: 1, d: 0.3,\n     height: 11}\n",
     "w.yaml:4: rocks[1].height: expected at most 10 m, got 11"),
    ("craters:\n  - {x: 3, y: 1, d: 0.3, deep: 0.2}\n",
     "w.yaml:2: craters[0].deep: unknown key (expected one of: x, y, d, depth)"),
    ("start: {box: middle, heading: 90}\n", "w.yaml:1: start.box: expected left or right"),
    ("start:\n  box: left\n  heading: 45\n",
     "w.yaml:3: start.heading: expected one of 0, 90, 180, 270 (degrees), got 45"),
    ("start: {box: left}\n", "w.yaml:1: start.heading: expected one of 0, 90, 180, 270"),
    ("start: {box: left, heading: 0, x: 0.1, y: 3.0}\n",
     "w.yaml:1: start: the footprint at x 0.1, y 3, yaw 0 is not wholly inside"),
    ("start:\n  {box: left, heading: 0, x: 0.8, y: 2.9}\nrocks: [{x: 1.2, y: 2.7, d: 0.25}]\n",
     "w.yaml:1: start: the footprint at x 0.8, y 2.9, yaw 0 overlaps rocks[0] at x 1.2"),
    ("start: {box: left, heading: 0, x: 0.8, y: 2.9}\ncraters: [{x: 0.5, y: 3, d: 0.2}]\n",
     "w.yaml:1: start: the footprint at x 0.8, y 2.9, yaw 0 overlaps craters[0]"),
    ("start: {box: left, heading: 90, x: 0.6, y: 3.28}\n",
     "w.yaml:1: start: the footprint at x 0.6, y 3.28, yaw 90 touches a wall"),
    ("start: {box: right, heading: 0}\nrocks: [{x: 1.4, y: 0.5, d: 0.3}]\n",
     "w.yaml:1: start: rocks[0] at x 1.4, y 0.5 reaches into the right start box"),
    ("rocks:\n  - {x: 7.3, y: 1.0, d: 0.3}\n",
     "w.yaml:2: rocks[0]: the disc at x 7.3, y 1, d 0.3 is not wholly inside"),
    ("rocks: {x: 1, y: 1, d: 0.2}\n", "w.yaml:1: rocks: expected a list of {x, y, d}"),
    ("rocks:\n  - 3\n", "w.yaml:2: rocks[0]: expected a mapping like"),
    ("rock: []\n", "w.yaml:1: rock: unknown key (expected one of: start, rocks, craters"),
    ("rocks: []\nrocks: []\n", "w.yaml:2: rocks: key given twice"),
    ("rocks: [{x: true, y: 1, d: 0.2}]\n", "w.yaml:1: rocks[0].x: expected an x in metres, "
     "got true/false"),
    ("- 1\n- 2\n", "w.yaml:1: expected a mapping with start, rocks and craters, got a list"),
    ("rocks: [{x: 1\n", "w.yaml:2: not valid YAML"),
])
def test_mistakes_name_the_file_line_and_key(text: str, expected: str) -> None:
    found = errors(text)
    assert any(e.startswith(expected) for e in found), found


def test_every_mistake_is_reported_in_one_pass() -> None:
    found = errors("start: {box: up, heading: 90}\n"
                   "rocks:\n"
                   "  - {x: 2, y: 1, d: 0}\n"
                   "  - {x: 2, y: 1}\n"
                   "craters: [{x: 3, y: 1, d: 0.2, depth: -1}]\n")
    assert [e.split(": ")[0:2] for e in found] == [
        ["w.yaml:1", "start.box"], ["w.yaml:3", "rocks[0].d"], ["w.yaml:4", "rocks[1].d"],
        ["w.yaml:5", "craters[0].depth"]]


def test_an_unreadable_file_is_an_error_naming_it(tmp_path: Path) -> None:
    with pytest.raises(WorldFileError, match="nope.yaml: cannot read"):
        load_world(tmp_path / "nope.yaml")


def test_a_start_box_given_over_a_world_file_may_not_start_on_an_obstacle(
        tmp_path: Path) -> None:
    # The file's left box is clear; --start-box right puts the seed's pose on the rock. The
    # physics would push the robot out unseen and the trace's referee count a collision.
    from ramp.simulation.mission import MissionOptions, make_world

    world = tmp_path / "w.yaml"
    world.write_text("start: {box: left, heading: 0}\nrocks: [{x: 0.7, y: 0.9, d: 0.3}]\n")
    with pytest.raises(ValueError, match="touches rock 0"):
        make_world(MissionOptions(world=str(world), start_box="right", heading=0))
    assert make_world(MissionOptions(world=str(world))).contacts() == []
