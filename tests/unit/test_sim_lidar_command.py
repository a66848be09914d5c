"""`ramp sim lidar`: one emulated scan, printed or drawn; bad input exits 2 naming the spot."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ramp.cli import main

REPO = Path(__file__).resolve().parents[2]
DEFAULT = str(REPO / "examples" / "worlds" / "default.yaml")


def test_json_gives_the_pose_the_counts_and_every_range(capsys: pytest.CaptureFixture[str],
                                                        ) -> None:
    code = main(["sim", "lidar", "--world", DEFAULT, "--at", "3.0,1.94,0", "--json"])
    assert code == 0
    doc = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert doc["pose"]["x"] == pytest.approx(3.0) and doc["pose"]["yaw"] == pytest.approx(0.0)
    assert len(doc["ranges_mm"]) == 1081
    assert abs(doc["ranges_mm"][540] - 3980) < 80  # the far wall, 3.98 m ahead of the scanner
    assert doc["hits"]["wall"] > 900 and doc["hits"]["frame"] > 0
    assert len(doc["rocks"]) == 3 and doc["rule_notes"] == []


def test_tilt_and_pan_change_what_is_seen(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "lidar", "--seed", "3", "--at", "1.2,1.94,0", "--tilt", "20",
                 "--json"]) == 0
    tilted = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert tilted["hits"]["ground"] > 200
    assert main(["sim", "lidar", "--seed", "3", "--at", "1.2,1.94,0", "--pan", "90",
                 "--json"]) == 0
    panned = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert abs(panned["ranges_mm"][540] - (3880 - 1940)) < 80  # the left wall


def test_plot_writes_a_png_and_the_text_summary_says_so(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str],
                                                        ) -> None:
    out = tmp_path / "scan.png"
    assert main(["sim", "lidar", "--world", DEFAULT, "--at", "1.0,1.94,0", "--tilt", "20",
                 "--plot", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = capsys.readouterr().out
    assert "wall" in text and "ground" in text and str(out) in text


@pytest.mark.parametrize("at", ["1,2", "a,b,c", "1,2,3,4", "1,2,nan"])
def test_a_bad_pose_exits_2_saying_what_was_expected(at: str,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "lidar", "--seed", "1", f"--at={at}"]) == 2
    assert "--at: expected X,Y,YAW" in capsys.readouterr().err


def test_a_pose_outside_the_arena_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "lidar", "--seed", "1", "--at", "0.1,1.9,0"]) == 2
    assert "--at:" in capsys.readouterr().err


def test_a_bad_world_file_exits_2_with_file_line_key(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("start: {box: left, heading: 90}\nrocks:\n  - {x: 2.0, y: 1.0, d: huge}\n")
    assert main(["sim", "lidar", "--world", str(bad), "--at", "3,1.94,0"]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:3: rocks[0].d: expected a diameter in metres > 0" in err


def test_a_world_file_that_departs_from_the_rules_is_used_with_a_note(
        capsys: pytest.CaptureFixture[str]) -> None:
    practice = str(REPO / "examples" / "worlds" / "practice-field.yaml")
    assert main(["sim", "lidar", "--world", practice, "--at", "1.0,1.94,0"]) == 0
    assert "note: departs from the competition rules" in capsys.readouterr().out


def test_via_scip_the_driver_reads_the_very_same_scan_over_tcp(
        capsys: pytest.CaptureFixture[str]) -> None:
    args = ["sim", "lidar", "--seed", "4", "--at", "1.2,1.0,30", "--tilt", "15", "--json"]
    assert main(args) == 0
    direct = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert main([*args, "--via-scip"]) == 0
    via = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert via["via_scip"] is True and direct["via_scip"] is False
    assert via["ranges_mm"] == direct["ranges_mm"] and via["hits"] == direct["hits"]


@pytest.mark.parametrize("option, value", [("--tilt", "1e308"), ("--pan", "-1e308"),
                                           ("--tilt", "nan"), ("--pan", "inf"),
                                           ("--tilt", "361")])
def test_an_angle_out_of_range_is_a_usage_error(capsys: pytest.CaptureFixture[str],
                                                option: str, value: str) -> None:
    assert main(["sim", "lidar", "--at", "1.2,1.94,0", f"{option}={value}"]) == 2
    err = capsys.readouterr().err
    assert f"{option}: expected an angle in degrees, -360 to 360" in err
    assert "Traceback" not in err
