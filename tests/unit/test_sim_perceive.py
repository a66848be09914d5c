"""`ramp sim perceive`: the command, its JSON and its picture, and the flow's own decisions
(retaking what an IMU correction spoiled, no pose when lost), through the whole chain on the
rig. The accuracy bounds are `test_perception_chain.py`'s."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from firmware_like.marte import MarteWorld
from firmware_like.world_file import load_world
from ramp.cli import main
from ramp.simulation.perceive import perceive, yaw_error
from ramp.simulation.rig import load_autonomy_config

REPO = Path(__file__).resolve().parents[2]
DEFAULT = str(REPO / "examples" / "worlds" / "default.yaml")


def test_the_command_prints_the_json_and_draws_the_picture(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "perceive.png"
    code = main(["sim", "perceive", "--world", DEFAULT, "--at", "0.85,1.9,0", "--hint", "right",
                 "--fault", "gyro-drift", "--json", "--plot", str(png)])
    assert code == 0
    doc = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert set(doc["pose"]) == {"x", "y", "yaw", "confidence"}
    assert doc["pose"]["x"] == pytest.approx(0.85, abs=0.02)
    assert doc["pose"]["y"] == pytest.approx(1.9, abs=0.02)
    assert doc["pose"]["yaw"] == pytest.approx(0.0, abs=0.5)
    assert doc["pose"]["confidence"] >= 0.5
    assert doc["lost"] is False and doc["true_pose"] == {"x": 0.85, "y": 1.9, "yaw": 0.0}
    assert all(set(o) == {"kind", "x", "y", "d"} and o["kind"] in ("rock", "crater")
               for o in doc["obstacles"])
    world = load_world(DEFAULT)  # three rocks and two craters, all in view
    truth = [("rock", r.x, r.y, r.d) for r in world.rocks] + [
        ("crater", c.x, c.y, c.d) for c in world.craters]
    assert len(doc["obstacles"]) == len(truth) == 5
    for kind, x, y, d in truth:
        near = [o for o in doc["obstacles"] if math.hypot(o["x"] - x, o["y"] - y) < 0.1]
        assert len(near) == 1 and near[0]["kind"] == kind
        assert near[0]["d"] == pytest.approx(d, abs=0.05)
    assert doc["fault"] == "gyro-drift" and doc["hint"] == "right"
    assert 70 < doc["sweep_scans"] < 100 and doc["scans"] == 10
    assert png.stat().st_size > 50_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_the_command_speaks_plainly_without_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "perceive", "--seed", "3", "--at", "5.5,2.0,120"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("seed 3, fault none, hint none")
    assert "estimated pose: x 5.50" in out and "(confidence 1.00)" in out
    assert "true pose:      x 5.500 y 2.000 yaw 120.0 deg" in out and "obstacles (" in out


def test_a_robot_put_on_a_rock_is_judged_where_the_world_pushed_it(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "perceive", "--seed", "3", "--at", "3.0,2.0,120", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert "pushed" in doc["moved_off"] and doc["true_pose"]["x"] != 3.0
    assert doc["pose"]["x"] == pytest.approx(doc["true_pose"]["x"], abs=0.02)
    assert doc["pose"]["y"] == pytest.approx(doc["true_pose"]["y"], abs=0.02)


def test_without_a_hint_the_ahrs_starts_within_20_degrees_and_the_run_repeats(
        capsys: pytest.CaptureFixture[str]) -> None:
    def once() -> dict[str, object]:
        assert main(["sim", "perceive", "--seed", "5", "--at", "1.0,1.0,90", "--json"]) == 0
        doc: dict[str, object] = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        doc.pop("wall_time_s")
        doc.pop("cpu_s")
        return doc

    a, b = once(), once()
    assert a == b
    prior = a["yaw_prior"]
    assert isinstance(prior, float)
    assert prior == pytest.approx(90.0 + math.degrees(yaw_error(5)), abs=0.5)
    assert 0.0 < abs(prior - 90.0) <= 20.5
    assert a["pose"] is not None and a["lost"] is False


def test_a_wrong_start_box_is_lost_with_no_pose_no_sweep_of_obstacles_and_a_reason(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "perceive", "--world", DEFAULT, "--at", "0.8,1.0,0", "--hint", "left",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert doc["pose"] is None and doc["lost"] is True and doc["obstacles"] == []
    assert doc["true_pose"] == {"x": 0.8, "y": 1.0, "yaw": 0.0}
    assert "start box" in doc["reason"] or "rule out" in doc["reason"]
    assert doc["relevels"] == 0  # a floor that agrees with the AHRS: the loss is real


def test_an_imu_shift_during_the_sweep_is_caught_while_parked_and_everything_taken_again(
        ) -> None:
    world = MarteWorld(seed=4, layout=load_world(DEFAULT))
    world.place(0.85, 1.9, 0.0)
    result = perceive(world, load_autonomy_config(), seed=4, fault="imu-shift", hint="right",
                      shift_window_s=(6.0, 7.0))
    assert 6.0 <= result.fault_info["at_s"] <= 7.0
    assert result.imu_suspect and "parked" in result.imu_suspect_reason
    assert result.imu_correction_deg == pytest.approx(result.fault_info["deg"], abs=0.5)
    assert not result.lost and len(result.obstacles) == 5
    assert result.plan is not None and len(result.sweep_records) == result.plan.scans
    assert result.retakes == 1 and result.relevels == 0  # localized and swept again
    assert all(r.t > 7.0 for r in result.sweep_records)  # the spoiled sweep was dropped
    assert result.sim_time_s > 2.0 + 2 * 9.0  # two sweeps


@pytest.mark.parametrize("args, message", [
    (["--at", "1,2"], "--at: expected X,Y,YAW"),
    (["--at", "0.1,0.1,0"], "outside the"),
    (["--at", "0.8,2.9,1e308"], "--at: expected a yaw in degrees"),
    (["--at", "0.8,2.9,0", "--seed", "-1"], "--seed: expected a whole number"),
    (["--at", "0.8,2.9,0", "--seed", "99999999999"], "--seed: expected a whole number"),
    (["--at", "1,1,0", "--world", "/nonexistent.yaml"], "nonexistent.yaml"),
])
def test_bad_input_exits_2_saying_what_was_expected(args: list[str], message: str,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "perceive", *args]) == 2
    assert message in capsys.readouterr().err
