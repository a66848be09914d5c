"""The console's small pure pieces, its command line, and the package boundary."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ramp.mcp.messages import Request, Response
from ramp.teleop.cli import main
from ramp.teleop.console import call_text, is_motion, pad_from_json, refused_modules


def test_call_text_takes_commas_or_blanks() -> None:
    assert call_text("base:base.drive", " 50, 0 ") == "base:base.drive=(50,0)"
    assert call_text("base:base.drive", "50 0") == "base:base.drive=(50,0)"
    assert call_text("ble:lift.extend", "") == "ble:lift.extend=()"


def test_motion_is_anything_but_reads_stops_and_robot_requests() -> None:
    assert is_motion(Request("base", "lf_wheel", "vel", ("1",)))
    assert is_motion(Request("ble", "lift", "extend"))
    assert not is_motion(Request("base", "base", "get"))
    assert not is_motion(Request("base", "base", "stop"))
    assert not is_motion(Request("robot", "control", "acquire", ("x",)))


def test_refused_modules_come_from_error_rows() -> None:
    sent = [Request("base", "base", "drive", ("1", "0")), Request("ble", "chain", "vel", ("1",))]
    rows = [Response("base", "base", "error", ("not_owner", "owned by autonomy"))]
    assert refused_modules(sent, rows) == {"base"}
    assert refused_modules(sent, []) == set()


def test_pad_from_json_reads_standard_pads_only_and_clamps() -> None:
    data = {"mapping": "standard", "axes": [0.5, -2, "x"],
            "buttons": [[True, 1], [False, 0.3], 0.9, None]}
    state = pad_from_json(data)
    assert state is not None
    assert state.axes == (0.5, -1.0, 0.0)
    assert state.pressed == (True, False, True, False)
    assert state.values == (1.0, 0.3, 0.9, 0.0)
    assert pad_from_json({**data, "mapping": ""}) is None
    assert pad_from_json(None) is None
    assert pad_from_json({"mapping": "standard", "axes": 3, "buttons": []}) is None


def test_a_broken_profile_stops_the_start_with_file_and_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    profiles = tmp_path / "ramp" / "profiles"
    profiles.mkdir(parents=True)
    (profiles / "mine.yaml").write_text("bindings:\n  - request: nope\n    press: 1\n")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    assert main(["--profile", "mine", "--http-port", "0"]) == 2
    err = capsys.readouterr().err
    assert "mine.yaml:2: bindings.0.request: 'nope' is not a request target" in err
    assert main(["--profile", "absent"]) == 2
    assert "no profile named 'absent'" in capsys.readouterr().err


def test_a_bad_backend_address_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--backend", "host:99999"]) == 2
    assert "--backend" in capsys.readouterr().err
    assert main(["--autonomy", "host:99999"]) == 2
    assert "--autonomy" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--name", "none"])


@pytest.mark.parametrize("hz", ["1e-300", "0.05", "0", "nan", "101"])
def test_a_poll_rate_out_of_range_is_a_usage_error(capsys: pytest.CaptureFixture[str],
                                                   hz: str) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--poll-hz", hz])
    assert info.value.code == 2
    assert "expected 0.1 <= HZ <= 100" in capsys.readouterr().err


def test_the_console_never_imports_the_backend() -> None:
    code = (
        "import sys, ramp.teleop.cli, ramp.teleop.app, ramp.teleop.console\n"
        "bad = [m for m in sys.modules if m.split('.')[:2] in ("
        "['ramp','layers'],['ramp','functional'],['ramp','hal'],['ramp','server'],"
        "['ramp','supervisor'],['ramp','config'],['ramp','sim'],['ramp','autonomy'])"
        " or m.startswith('firmware_like')]\n"
        "print(bad)\n"
        "sys.exit(1 if bad else 0)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr


def _console_with(describe: list[str]) -> tuple[object, list[dict[str, object]]]:
    from types import SimpleNamespace

    from ramp.mcp.describe import build_catalog
    from ramp.mcp.protocol import parse_response_line
    from ramp.teleop.console import Console
    from ramp.teleop.profile import DEFAULT_PROFILE, ProfileLibrary

    library = ProfileLibrary()
    console = Console("127.0.0.1", 9, name="op", library=library,
                      profile=library.load(DEFAULT_PROFILE))
    console._loop = SimpleNamespace(time=lambda: 1.0)  # type: ignore[assignment]
    got: list[dict[str, object]] = []
    console.pages["1"] = got.append
    rows = [r for line in describe for r in parse_response_line(line.encode())]
    console.poller.catalog = build_catalog(
        [r for r in rows if r.module == "robot"],
        {m: [r for r in rows if r.module == m] for m in {r.module for r in rows} - {"robot"}})
    return console, got


def test_an_info_interlock_is_an_events_line_and_no_alert_a_warning_one_is_an_alert() -> None:
    """Issue 35: MARTE's digging_creep was a banner for the whole of every dig."""
    from ramp.teleop.robot import Status

    console, got = _console_with([
        "robot:robot.module=(base)", "robot:interlock.rule=(digging_creep,info)",
        "robot:interlock.rule=(bumper,error)",
        "robot:interlock.message=(bumper,Back away from what the bumper touches)"])
    status = Status(reachable=True, polls=1,
                    values={"robot:interlock.active": "digging_creep"})
    console.poller.status = status
    console._on_status(status)  # type: ignore[attr-defined]
    events = [m["text"] for m in got if m["type"] == "event"]
    assert events == ["interlock digging_creep active (info)"]
    assert console.alerts.alerts == []  # type: ignore[attr-defined]
    status.values["robot:interlock.active"] = "none"
    console._on_status(status)  # type: ignore[attr-defined]
    assert [m["text"] for m in got if m["type"] == "event"][-1] == \
        "interlock digging_creep released (info)"
    status.values["robot:interlock.active"] = "bumper"
    console._on_status(status)  # type: ignore[attr-defined]
    (alert,) = console.alerts.view()  # type: ignore[attr-defined]
    assert alert["severity"] == "error" and alert["takeover"]
    assert alert["text"].startswith("Back away from what the bumper touches.")
    catalog = console.catalog_message()  # type: ignore[attr-defined]
    assert catalog["interlocks"]["digging_creep"] == {"severity": "info", "message": ""}


def test_the_low_battery_alert_reads_the_robot_s_charge_where_it_gives_one() -> None:
    from ramp.teleop.console import battery_keys

    console, _ = _console_with([
        "robot:robot.module=(base)", "base:battery.property=(volt,float,V)",
        "base:battery.property=(charge,float,%)", "base:aux.property=(volt,float,V)"])
    assert battery_keys(console.poller.catalog) == (  # type: ignore[attr-defined]
        "base:battery.charge", "base:aux.volt")
