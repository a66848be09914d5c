"""A simulated MARTE run recorded by the supervisor itself on a virtual clock
(tests/hil_sim/recorder_sample.py) and read back with the `mcap` reader: schemas, MCP lines
per client in order, 10 Hz sampling, commands matching what the Sabertooth emulators
received, events, and the summary. (tests/hil_sim/test_recorder_run.py does the same
against real `ramp run --record` processes on the wall clock.)"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from mcap.reader import make_reader

from ramp.recorder.logcli import main as log_main
from tests.hil_sim.recorder_sample import DURATION, record_sample


@pytest.fixture(scope="module")
def sample(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    return record_sample(tmp_path_factory.mktemp("rec"))


@pytest.fixture(scope="module")
def messages(sample: tuple[Path, dict[str, Any]]) -> list[tuple[str, int, Any, Any]]:
    with open(sample[0], "rb") as f:
        reader = make_reader(f)
        return [(ch.topic, m.log_time, json.loads(m.data), json.loads(s.data))
                for s, ch, m in reader.iter_messages(log_time_order=False)]


def test_every_message_matches_its_channels_schema(messages: list[Any]) -> None:
    topics = {topic for topic, *_ in messages}
    assert topics == {"/mcp/in", "/mcp/out", "/robot/get", "/base/get", "/ble/get",
                      "/robot/commands", "/robot/events", "/robot/module_state", "/log"}
    validators: dict[str, Any] = {}
    for topic, _, data, schema in messages:
        if topic not in validators:
            jsonschema.validators.validator_for(schema).check_schema(schema)
            validators[topic] = jsonschema.validators.validator_for(schema)(schema)
        validators[topic].validate(data)


def test_each_clients_lines_are_recorded_in_order_with_their_answers(
        sample: tuple[Path, dict[str, Any]], messages: list[Any]) -> None:
    sent = sample[1]["sent"]
    assert len(sent) == 3
    for client, lines in sent.items():
        ins = [d["line"] for tp, _, d, _ in messages if tp == "/mcp/in" and d["client"] == client]
        outs = [d["line"] for tp, _, d, _ in messages if tp == "/mcp/out" and d["client"] == client]
        assert ins == lines and len(outs) == len(lines)
    shell = [c for c, lines in sent.items() if "base:lf_wheel.vel=(300)" in lines][0]
    outs = [d["line"] for tp, _, d, _ in messages if tp == "/mcp/out" and d["client"] == shell]
    assert outs[0].startswith("base:lf_wheel.error=(bad_params,")
    assert outs[1].startswith("ble:chain.error=(not_owner,")


def test_health_and_get_rows_come_at_10_hz(messages: list[Any]) -> None:
    for topic in ("/robot/get", "/base/get", "/ble/get"):
        times = [t for tp, t, *_ in messages if tp == topic]
        rate = (len(times) - 1) / ((times[-1] - times[0]) / 1e9)
        assert 9.0 <= rate <= 11.0, (topic, rate)
        assert len(times) >= 0.9 * 10 * DURATION


def test_commands_match_what_the_emulators_received(sample: tuple[Path, dict[str, Any]],
                                                    messages: list[Any]) -> None:
    received: dict[str, list[float]] = sample[1]["emulator"]
    commanded: dict[str, list[float]] = {}
    for tp, _, d, _ in messages:
        if tp == "/robot/commands" and d["kind"] == "motor":
            seq = commanded.setdefault(d["channel"], [])
            if not seq or seq[-1] != d["duty"]:
                seq.append(d["duty"])
    assert set(commanded) == set(received) == {
        "base.lf_wheel", "base.lb_wheel", "base.rf_wheel", "base.rb_wheel", "ble.chain_left",
        "ble.chain_right", "ble.lift_motor"}
    step = 1 / 127  # the Sabertooth's resolution
    for label, got in received.items():
        # Each value on the wire is a recorded command (the newest wins, so a command
        # superseded before it went out may be missing from the wire, never the reverse).
        want = commanded[label]
        i = 0
        for value in got:
            while i < len(want) and abs(want[i] - value) > step:
                i += 1
            assert i < len(want), f"{label}: {value} reached the wire but was not recorded"
        assert abs(want[-1] - got[-1]) <= step
    assert max(commanded["base.lf_wheel"]) == pytest.approx(1.0)
    assert min(commanded["base.rf_wheel"]) == pytest.approx(-1.0)  # polarity -1


def test_the_summary_tells_the_run(sample: tuple[Path, dict[str, Any]],
                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert log_main(["summary", str(sample[0]), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert len(r["clients"]) == 3 and r["duration_s"] == pytest.approx(DURATION, abs=0.1)
    assert [o["owner"] for o in r["owners"]] == ["operator"]
    assert len(r["watchdog_trips"]) == 1 and 24.0 <= r["watchdog_trips"][0] <= 24.5
    assert r["error_responses"] == {"bad_params": 1, "not_owner": 1}
    assert r["motion_s"]["base"] == pytest.approx(17.5, abs=0.2)  # 0.5-13 s, 35-40 s
    assert r["motion_s"]["ble"] > 15
    volt = r["battery"]["base:battery.volt"]
    assert 15 < volt["min"] < volt["max"] < 30
    assert r["log"]["warnings"] >= 1  # the watchdog's own warning, through the log handler
    assert r["recorder_dropped"] == 0 == sample[1]["dropped"]
    assert r["events"]["control"] == 2  # acquired, released


def test_events_and_module_states_are_the_supervisors_own(messages: list[Any]) -> None:
    events = [(t, d["kind"], d["text"]) for tp, t, d, _ in messages if tp == "/robot/events"]
    kinds = [k for _, k, _ in events]
    assert kinds.count("watchdog_trip") == 1
    trip = next(e for e in events if e[1] == "watchdog_trip")
    assert trip[2] == "every module stopped: expired"
    start = messages[0][1]
    assert 24.2 <= (trip[0] - start) / 1e9 <= 24.3  # 1 s after the last heartbeat (23.25 s)
    assert [e[2].split(" (")[0] for e in events if e[1] == "control"] == ["operator", "released"]
    assert ("watchdog", "armed: motion") in [(k, x) for _, k, x in events]
    states = [(d["module"], d["state"]) for tp, _, d, _ in messages
              if tp == "/robot/module_state"]
    assert states == [("base", "ok"), ("ble", "ok")]  # attached at start, before any client
    health = [d for tp, _, d, _ in messages if tp == "/robot/get"]
    assert all(h["recorder"]["dropped"] == 0 for h in health)


def test_the_plot_is_drawn(sample: tuple[Path, dict[str, Any]], tmp_path: Path) -> None:
    out = tmp_path / "plot.png"
    assert log_main(["plot", str(sample[0]), "-o", str(out)]) == 0
    assert out.stat().st_size > 50_000
