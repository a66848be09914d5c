"""`ramp log summary` and `ramp log plot` on a synthetic recording whose facts are known:
two clients, two owners, one watchdog trip, one fault, two overruns, the Base moving for
3 s and the BLE for 1 s, the battery between 24.2 and 25.1 V."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ramp.cli import main as ramp_main
from ramp.mcp.messages import Response
from ramp.recorder import Recorder, RecorderConfig
from ramp.recorder.logcli import main
from ramp.recorder.plot import PlotData
from ramp.recorder.reading import Recording
from ramp.recorder.summary import Summary
from ramp.recorder.writer import recording_files

ORIGIN = 1_779_285_600_000_000_000  # 2026-05-20 14:00:00 UTC
WHEELS = ("lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel")


def health(t: float, wd: str, owner: str, overruns: int, ble: str) -> list[Response]:
    return [Response("robot", "robot", "uptime", (t,)),
            Response("robot", "tick", "late", (100, 250, 400 + int(t * 10))),
            Response("robot", "tick", "overruns", (overruns,)),
            Response("robot", "watchdog", "state", (wd,)),
            Response("robot", "control", "owner", (owner,)),
            Response("robot", "clients", "count", (2,)),
            Response("robot", "base", "state", ("ok",)),
            Response("robot", "ble", "state", (ble,))]


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Ten seconds of a made-up run, health and gets at 10 Hz."""
    d = tmp_path_factory.mktemp("rec")
    rec = Recorder(RecorderConfig(str(d)), origin_ns=ORIGIN)
    rec.start(100.0)
    for k in range(101):
        t = 100.0 + k * 0.1
        s = t - 100.0
        wd = "tripped" if 5.0 <= s < 5.5 else "armed" if 1.0 <= s < 5.0 else "idle"
        owner = "operator" if 2.0 <= s < 8.0 else "autonomy" if s >= 8.0 else "none"
        rec.health(t, health(s, wd, owner, 0 if s < 7 else 2, "fault" if s >= 6 else "ok"))
        moving = 1.0 <= s < 4.0
        rec.module_rows(t, "base", [
            *(Response("base", w, "vel", (60 if moving else 0,)) for w in WHEELS),
            Response("base", "battery", "volt", (round(25.1 - 0.09 * s, 3),)),
            Response("base", "l_button", "press", (0,))])
        rec.module_rows(t, "ble", [Response("ble", "lift", "pos", (min(1.0, s / 10),)),
                                   Response("ble", "lift", "vel", (0,)),
                                   Response("ble", "chain", "vel", (80 if 2 <= s < 3 else 0,)),
                                   Response("ble", "load", "kg", (s * 0.5,))])
    for s, duty in ((1.0, 0.6), (4.0, 0.0)):
        for w in WHEELS:
            rec.command(100.0 + s, "base_motors", f"base.{w}", -duty if w[0] == "r" else duty)
    rec.command(102.0, "ble_motors", "ble.chain_left", 0.8)
    rec.command(103.0, "ble_motors", "ble.chain_left", 0.0)
    for i in range(20):
        rec.mcp_in(100.0 + i * 0.2, "127.0.0.1:41000", "base:base.drive=(60,0)")
        rec.mcp_out(100.0 + i * 0.2, "127.0.0.1:41000", "")
    rec.mcp_in(101.0, "127.0.0.1:42000", "base:lf_wheel.vel=(300)")
    rec.mcp_out(101.0, "127.0.0.1:42000",
                "base:lf_wheel.error=(bad_params,vel takes one int in -100..100)")
    rec.event(102.0, "control", "control acquired by operator")
    rec.event(105.0, "watchdog_trip", "operator silent for 1.00 s")
    rec.module_state(106.0, "ble", "fault", "bus ble_motors: read error")
    rec.event(108.0, "control", "control taken over: operator -> autonomy")
    rec.log(106.0, 4, "module ble fault: bus ble_motors: read error", "ramp.supervisor", "x", 1)
    rec.log(105.0, 3, "watchdog expired", "ramp.robot", "x", 2)
    rec.close()
    return recording_files(d)[0][1]


def test_summary_reports_what_happened(recording: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["summary", str(recording), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["duration_s"] == 10.0 and r["start_utc"] == "2026-05-20 14:00:00 UTC"
    assert r["clients"] == {"127.0.0.1:41000": {"messages": 20, "first_s": 0.0, "last_s": 3.8},
                            "127.0.0.1:42000": {"messages": 1, "first_s": 1.0, "last_s": 1.0}}
    assert r["error_responses"] == {"bad_params": 1}
    assert r["owners"] == [{"owner": "operator", "since_s": 2.0, "held_s": 6.0},
                           {"owner": "autonomy", "since_s": 8.0, "held_s": 2.0}]
    assert r["watchdog_trips"] == [5.0]
    assert r["faults"] == {"ble": [6.0]}
    assert r["overruns"] == 2 and r["tick_late_max_us"] == 500
    assert r["motion_s"] == {"base": 3.0, "ble": 1.0}
    assert r["battery"] == {"base:battery.volt": {"min": 24.2, "max": 25.1, "last": 24.2}}
    assert r["log"]["warnings"] == 1 and r["log"]["errors"] == 1
    assert r["recorder_dropped"] == 0
    assert r["files"][0]["complete"] is True


def test_summary_text_is_one_screen_a_person_reads(recording: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert ramp_main(["log", "summary", str(recording)]) == 0  # through `ramp log`
    text = capsys.readouterr().out
    for expected in ("recorded   2026-05-20 14:00:00 UTC, 10.0 s",
                     "owners     operator (from 2 s, 6 s), autonomy (from 8 s, 2 s)",
                     "watchdog   1 trip (at 5 s)", "faults     ble: 1 (at 6 s)",
                     "overruns   2", "motion     base 3 s, ble 1 s",
                     "battery    base:battery.volt: min 24.2 V, max 25.1 V",
                     "log        1 warning, 1 error", "recorder   0 records dropped"):
        assert expected in text, text


def test_summary_without_events_falls_back_on_the_health_rows(recording: Path) -> None:
    """A supervisor that records no events still gets trips, faults and owners counted."""
    s = Summary()
    for msg in Recording([recording]):
        if msg.topic not in ("/robot/events", "/robot/module_state"):
            s.add(msg)
    r = s.report()
    assert r["watchdog_trips"] == [5.0] and r["faults"] == {"ble": [6.0]}
    assert [o["owner"] for o in r["owners"]] == ["operator", "autonomy"]


def test_a_file_cut_short_is_summarised_and_said_to_be_cut(
        recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = recording.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) - 100])  # the index and footer are lost
    assert main(["summary", str(cut), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["files"][0]["complete"] is False and "cut by a crash" in r["files"][0]["truncated"]
    assert r["watchdog_trips"] == [5.0] and r["duration_s"] == 10.0
    assert main(["summary", str(cut)]) == 0
    assert "cut short: the file ends in the middle of a record" in capsys.readouterr().out


def test_plot_draws_every_panel_and_marks_events(recording: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run.png"
    assert main(["plot", str(recording), "-o", str(out), "--progress"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
    assert f"wrote {out}" in capsys.readouterr().out
    data = PlotData()
    for msg in Recording([recording]):
        data.add(msg)
    assert set(data.battery) == {"base:battery"}
    assert set(data.commands) == {"base_motors", "ble_motors"}
    assert set(data.commands["base_motors"]) == {f"base.{w}" for w in WHEELS}
    assert {"vel", "pos", "kg", "press"} <= set(data.props)
    assert set(data.late) == {"p50", "p99", "max"}
    assert data.all_marks() == {"control": [2.0, 8.0], "watchdog_trip": [5.0], "fault": [6.0],
                                "log_error": [6.0]}


def test_progress_is_shown_when_asked(recording: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["summary", str(recording), "--progress"]) == 0
    assert "reading" in capsys.readouterr().err


def test_missing_and_foreign_files_are_refused_with_status_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["summary", str(tmp_path / "nope.mcap")]) == 2
    assert "no such file" in capsys.readouterr().err
    bad = tmp_path / "bad.mcap"
    bad.write_text("not a recording at all")
    assert main(["plot", str(bad), "-o", str(tmp_path / "x.png")]) == 2
    assert "not an MCAP file" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["summary", "plot"])
def test_an_empty_file_name_is_a_usage_error(command: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """`ramp log summary ""` said `.: cannot read: it is a directory`."""
    with pytest.raises(SystemExit) as exc:
        main([command, "", "-o", "x.png"] if command == "plot" else [command, ""])
    assert exc.value.code == 2
    assert "expected a recording (FILE.mcap), got an empty name" in capsys.readouterr().err


def test_plot_without_matplotlib_says_what_to_install(
        recording: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if the `log` extra were absent
    assert main(["plot", str(recording), "-o", str(tmp_path / "x.png")]) == 2
    assert "pip install '.[log]'" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "tqdm", None)
    assert main(["summary", str(recording), "--progress"]) == 0  # no bar, same summary
    assert "watchdog   1 trip" in capsys.readouterr().out


def _crafted(tmp_path: Path) -> Path:
    """A recording whose log and event texts carry terminal escapes (ESC, BEL)."""
    rec = Recorder(RecorderConfig(str(tmp_path)), origin_ns=ORIGIN)
    rec.start(100.0)
    for k in range(3):
        rec.health(100.0 + k, health(float(k), "idle", "none", 0, "ok"))
    rec.event(101.0, "control", "owner \x1b]0;pwned\x07 \x1b[2J")
    rec.log(101.0, 4, "bad \x1b[31mred\x1b[0m \x07 bell", "ramp.supervisor", "x", 1)
    rec.close()
    return recording_files(tmp_path)[0][1]


def test_summary_shows_control_characters_escaped_never_raw(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _crafted(tmp_path)
    assert main(["summary", str(path)]) == 0
    text = capsys.readouterr().out
    assert "\x1b" not in text and "\x07" not in text
    assert "\\x1b" in text and "\\x07" in text, text


def test_summary_into_a_reader_that_stops_early_ends_quietly(tmp_path: Path) -> None:
    path = _crafted(tmp_path)
    # `head -n 0` exits before Python has started: the first write finds the pipe closed,
    # as a `| head` does after its lines in a longer summary.
    proc = subprocess.run(f"{sys.executable} -m ramp.cli log summary {path} | head -n 0",
                          shell=True, capture_output=True, text=True, timeout=120,
                          cwd=Path(__file__).resolve().parents[2])
    assert proc.stdout == ""
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr, proc.stderr
