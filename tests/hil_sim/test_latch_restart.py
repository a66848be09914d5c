"""Latches survive a restart and are reset only once their cause is gone (SPEC 2.2, issue 33
item 3): a lift stall and Scout's bumper interlock latched, the supervisor shut down and
built again on the same state file, watched over MCP and on the emulated wire."""

from __future__ import annotations

import json
import logging
import math
import socket
import time
from pathlib import Path

import pytest

from ramp.runtime.latch_state import LatchState, state_file
from tests.harness import SCOUT_YAML, SimHarness, ask_line, start_ramp, stop_process, value
from tests.harness import TestClient as Client


def stalled(c: Client) -> str:
    return value(c.ask("ble:ble.get=()"), "ble:lift.stalled")


def lift_wire(h: SimHarness) -> float:
    return float(h.backplane.sabertooth["ble_motors"].emulator.duty(131, 1))


def latch_the_lift(h: SimHarness, c: Client) -> None:
    assert c.ask("sim:lift.jam=(1)ble:lift.extend=()") == ""
    for _ in range(20):
        h.advance(0.1)
        assert c.ask("") == ""
    assert stalled(c) == "1"
    assert lift_wire(h) == 0.0


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return state_file(tmp_path, "ramp.yaml")


def marte(path: Path) -> SimHarness:
    return SimHarness(latch_state=LatchState(path, "ramp.yaml"))


def test_a_latched_stall_survives_a_restart_until_reset(path: Path) -> None:
    h = marte(path)
    latch_the_lift(h, h.connect())
    h.close()
    kept = json.loads(path.read_text())
    assert list(kept["devices"]) == ["ble:lift"]
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary left

    h = marte(path)  # the restart: a fresh world, the rock gone, nobody has looked yet
    try:
        c = h.connect()
        assert stalled(c) == "1"
        got = c.ask("ble:lift.extend=()")
        assert got.startswith("ble:lift.error=(fault,lift stalled: ") and \
            "latched before the restart" in got, got
        h.advance(0.5)
        assert lift_wire(h) == 0.0
        assert c.ask("ble:lift.reset=()") == ""
        h.advance(0.2)  # the task writes the file at 10 Hz
        assert json.loads(path.read_text())["devices"] == {}
        assert c.ask("ble:lift.extend=()") == ""
        h.advance(0.3)
        assert lift_wire(h) > 0
    finally:
        h.close()
    h = marte(path)  # reset before the restart: nothing latched after it
    try:
        assert stalled(h.connect()) == "0"
    finally:
        h.close()


@pytest.mark.parametrize("text", ["{", "", "[]", '{"format": 1, "devices": {"ble:lift": 3}, '
                                  '"interlocks": []}', "\udcff"])
def test_an_unreadable_state_file_starts_every_latch_latched(
        path: Path, text: str, caplog: pytest.LogCaptureFixture) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    with caplog.at_level(logging.WARNING, logger="ramp.latches"):
        h = marte(path)
    try:
        assert any("cannot be read" in r.getMessage() and "starts latched" in r.getMessage()
                   for r in caplog.records)
        c = h.connect()
        assert stalled(c) == "1"
        assert c.ask("ble:lift.vel=(20)").startswith("ble:lift.error=(fault,latched at start")
        assert c.ask("ble:lift.reset=()") == ""
        h.advance(0.2)
        assert json.loads(path.read_text())["devices"] == {}  # rewritten, readable again
    finally:
        h.close()


def test_a_missing_state_file_is_a_first_start(path: Path,
                                               caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="ramp.latches"):
        h = marte(path)
    try:
        assert any("first start" in r.getMessage() for r in caplog.records)
        assert stalled(h.connect()) == "0"
        assert json.loads(path.read_text()) == {"config": "ramp.yaml", "devices": {},
                                                "format": 1, "interlocks": []}
    finally:
        h.close()


def test_reset_is_refused_while_the_cause_reads_true(path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    h = marte(path)
    try:
        c = h.connect()
        latch_the_lift(h, c)
        lift = h.sup.slots["ble"].module.lift  # type: ignore[attr-defined]
        volts = [math.nan]  # the pot's reading lost (a broken wire), the module attached
        monkeypatch.setattr(lift.pot, "read", lambda: volts[0])
        got = c.ask("ble:lift.reset=()")
        assert got.startswith("ble:lift.error=(fault,ble:lift stays latched: the lift's "
                              "position cannot be read"), got
        assert stalled(c) == "1"
        volts[0] = 1.0
        assert c.ask("ble:lift.reset=()") == ""
        assert stalled(c) == "0"
        monkeypatch.setattr(lift.latch, "cause", lambda: 1 / 0)  # a cause that raises
        latch_the_lift(h, c)
        got = c.ask("ble:lift.reset=()")
        assert "its cause cannot be read; ZeroDivisionError" in got, got
    finally:
        h.close()


def test_a_latched_interlock_survives_a_restart(tmp_path: Path) -> None:
    path = state_file(tmp_path, "scout.yaml")

    def scout() -> SimHarness:
        return SimHarness(SCOUT_YAML, marte=False, latch_state=LatchState(path, "scout.yaml"))

    h = scout()
    c = h.connect()
    assert c.ask("sim:input.set=(base,bumper_left,1)") == ""
    h.advance(0.2)
    assert c.ask("sim:input.clear=(base,bumper_left)") == ""
    h.advance(0.3)
    assert c.ask("base:base.drive=(20,0)").startswith("base:base.error=(interlocked,bumper")
    h.close()
    assert json.loads(path.read_text())["interlocks"] == ["bumper"]

    h = scout()  # the bumper is not pressed now, but nobody acknowledged the press
    try:
        c = h.connect()
        h.advance(0.1)
        assert "bumper" in value(c.ask("robot:robot.get=()"), "robot:interlock.active")
        assert c.ask("base:base.drive=(20,0)").startswith("base:base.error=(interlocked,bumper")
        assert c.ask("base:base.drive=(20,180)") == ""  # backing away is still allowed
        assert c.ask("robot:interlock.reset=(bumper)") == ""
        h.advance(0.2)
        assert c.ask("base:base.drive=(20,0)") == ""
        assert json.loads(path.read_text())["interlocks"] == []
    finally:
        h.close()


def test_ramp_run_keeps_a_latch_across_a_sigterm(tmp_path: Path) -> None:
    """The black box: `ramp run --sim --state-dir DIR`, the lift latched on the wall clock,
    SIGTERM, a second `ramp run` on the same directory."""
    args = ["--sim", "--port", "0", "--state-dir", str(tmp_path)]
    proc, host, port = start_ramp(args)
    try:
        with socket.create_connection((host, port)) as s:
            assert ask_line(s, "robot:watchdog.timeout=(10)sim:lift.jam=(1)"
                               "ble:lift.extend=()") == ""
            deadline = time.monotonic() + 10
            while value(ask_line(s, "ble:ble.get=()"), "ble:lift.stalled") != "1":
                assert time.monotonic() < deadline, "the lift never latched"
                time.sleep(0.1)
    finally:
        stop_process(proc)
        proc.communicate()
    [kept] = tmp_path.glob("latches-ramp-*.json")
    assert "ble:lift" in json.loads(kept.read_text())["devices"]
    proc, host, port = start_ramp(args)
    try:
        with socket.create_connection((host, port)) as s:
            assert value(ask_line(s, "ble:ble.get=()"), "ble:lift.stalled") == "1"
            assert "latched before the restart" in ask_line(s, "ble:lift.vel=(10)")
    finally:
        stop_process(proc)
        proc.communicate()
