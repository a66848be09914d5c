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
