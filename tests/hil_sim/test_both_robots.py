"""One contract, every robot (SPEC 10, STYLE "one contract suite, many targets"): MARTE and
Scout on their emulators, and nothing here names a device. Everything a test needs is found
through `describe`, as ramp-shell and the console find it, so a module from a plugin (Scout's
arm) gets the same checks as RAMP's own."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from ramp.mcp.messages import Response
from ramp.mcp.protocol import parse_response_line
from ramp.recorder import Recorder, RecorderConfig
from ramp.recorder.writer import recording_files
from tests import harness
from tests.harness import ROBOTS, SimHarness, robot_harness

KINDS = {"motion", "stop", "state", "read"}


@pytest.fixture(params=sorted(ROBOTS))
def robot(request: pytest.FixtureRequest) -> Iterator[SimHarness]:
    h = robot_harness(request.param)
    yield h
    h.close()


def modules(c: harness.TestClient) -> list[str]:
    line = c.ask("robot:robot.modules=()")
    m = re.fullmatch(r"robot:robot\.modules=\(([^)]*)\)", line)
    assert m, line
    return m.group(1).split(",")


def describe(c: harness.TestClient, module: str) -> list[Response]:
    return parse_response_line(c.ask(f"{module}:{module}.describe=()").encode())


def motions(c: harness.TestClient, module: str) -> list[str]:
    """A valid request for every motion function of `module` that takes parameters: the
    middle of each parameter's range, nudged off zero (a speed of 0 moves nothing)."""
    rows = describe(c, module)
    kinds = {(r.device, r.values[0]): r.values[1] for r in rows if r.prop == "kind"}
    out = []
    for r in rows:
        if r.prop != "function" or kinds[(r.device, r.values[0])] != "motion" or len(
                r.values) < 2:
            continue
        params = []
        for spec in r.values[1:]:
            m = re.fullmatch(r"(int|float) (-?[\d.]+)\.\.(-?[\d.]+)", str(spec))
            if m is None:
                params.append("0")
                continue
            lo, hi = float(m.group(2)), float(m.group(3))
            v = lo + 0.7 * (hi - lo)
            params.append(str(int(v)) if m.group(1) == "int" else f"{v:.1f}")
        out.append(f"{module}:{r.device}.{r.values[0]}=({','.join(params)})")
    return out


def all_motions(c: harness.TestClient) -> list[str]:
    return [req for m in modules(c) for req in motions(c, m)]


def moving(h: SimHarness) -> list[str]:
    return [name for name, slot in h.sup.slots.items() if slot.module.is_moving()]


def test_every_get_row_is_a_described_property_and_every_function_has_a_kind(
        robot: SimHarness) -> None:
    c = robot.connect()
    for module in modules(c):
        rows = describe(c, module)
        props = {(r.device, str(r.values[0])) for r in rows if r.prop == "property"}
        got = parse_response_line(c.ask(f"{module}:{module}.get=()").encode())
        assert {(r.device, r.prop) for r in got} == props
        functions = {(r.device, str(r.values[0])) for r in rows if r.prop == "function"}
        kinds = {(r.device, str(r.values[0])): str(r.values[1]) for r in rows
                 if r.prop == "kind"}
        assert set(kinds) == functions and set(kinds.values()) <= KINDS
        assert kinds[(module, "stop")] == "stop"


def test_every_motion_request_is_accepted_and_robot_stop_stops_everything(
        robot: SimHarness) -> None:
    c = robot.connect()
    requests = all_motions(c)
    assert len(requests) >= 4
    for req in requests:
        assert c.ask(req) == "", req
    robot.advance(0.2)
    c.ask("")
    assert moving(robot)
    assert c.ask("robot:robot.stop=()") == ""
    robot.advance(0.05)
    assert moving(robot) == []


def test_a_silent_commander_stops_every_module(robot: SimHarness) -> None:
    c = robot.connect()
    for req in all_motions(c):
        c.ask(req)
    robot.advance(0.2)
    c.ask("")
    assert moving(robot)
    robot.advance(1.2)  # past the 1 s watchdog timeout, silent
    assert "robot:watchdog.state=(tripped)" in c.ask("robot:robot.get=()")
    assert moving(robot) == []


def test_another_client_s_motion_is_refused_while_one_owns_control(robot: SimHarness) -> None:
    owner, other = robot.connect(), robot.connect()
    assert owner.ask("robot:control.acquire=(operator)") == ""
    for req in all_motions(other):
        module, device = req.split(".", 1)[0].split(":")
        assert other.ask(req).startswith(f"{module}:{device}.error=(not_owner,"), req
    assert moving(robot) == []


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_the_recorder_records_every_module_s_rows(name: str, tmp_path: Path) -> None:
    h = robot_harness(name, recorder=Recorder(RecorderConfig(str(tmp_path), 100, 5)))
    try:
        c = h.connect()
        for req in all_motions(c)[:2]:
            c.ask(req)
        h.advance(0.5)
        c.ask("")
    finally:
        h.close()
    files = recording_files(tmp_path)
    assert files
    from mcap.reader import make_reader

    topics: set[str] = set()
    with open(files[0][1], "rb") as f:
        for _schema, channel, _message in make_reader(f).iter_messages():
            topics.add(channel.topic)
    for module in h.config.modules:
        assert any(module in t for t in topics), (module, sorted(topics))
