"""`ramp sim perceive`: the flow (settle, level, localize, re-level, sweep, detect) on the rig,
its JSON and its picture.

The localizer and the obstacle detector are stand-ins that know the truth and check the
records against it (`perception_oracle.py`), so these tests prove the flow and everything
under it; the real modules' accuracy is their own tests' business.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from importlib.util import find_spec
from pathlib import Path

import pytest

import ramp.simulation.perceive as perceive_module
from firmware_like.marte import MarteWorld
from firmware_like.world_file import load_world
from ramp.cli import main
from ramp.simulation.perceive import PerceiveResult, perceive, yaw_error
from ramp.simulation.rig import Rig, load_autonomy_config
from tests.unit.perception_oracle import OracleDetector, OracleLocalizer

REPO = Path(__file__).resolve().parents[2]
DEFAULT = str(REPO / "examples" / "worlds" / "default.yaml")


def world_at(x: float, y: float, yaw: float, seed: int = 0) -> MarteWorld:
    world = MarteWorld(seed=seed, layout=load_world(DEFAULT))
    world.place(x, y, yaw)
    return world


def run(world: MarteWorld, seed: int = 0, **kw: object) -> tuple[PerceiveResult,
                                                                  OracleLocalizer]:
    oracle = OracleLocalizer(world)
    result = perceive(world, load_autonomy_config(), seed=seed, localize=oracle,
                      detect=OracleDetector(world), **kw)  # type: ignore[arg-type]
    return result, oracle


def test_with_the_hint_it_localizes_sweeps_and_sees_every_obstacle() -> None:
    world = world_at(0.8, 2.9, 0.0)
    result, oracle = run(world, hint="left")
    assert not result.lost and result.pose is not None
    assert (result.pose.x, result.pose.y) == (world.x, world.y)
    assert oracle.calls == [{"n": 10, "hint": "left", "yaw_prior": None}]
    assert result.relevels == 0 and not result.imu_suspect
    assert 300 < len(result.sweep_records) < 360  # 40 deg at 5 deg/s, 40 scans/s
    tilts = [r.tilt_deg for r in result.sweep_records]
    assert tilts[0] < 1.0 and tilts[-1] > 39.0
    seen = {(o.kind, o.x, o.y) for o in result.obstacles}
    assert seen == {(o.kind, o.x, o.y) for o in result.true_obstacles}  # all five in view
    assert result.sim_time_s < 12.0


def test_without_a_hint_the_ahrs_starts_within_20_degrees_and_the_run_repeats() -> None:
    def once() -> dict[str, object]:
        result, oracle = run(world_at(1.0, 1.0, 90.0, seed=5), seed=5)
        doc = result.to_json()
        assert oracle.calls[0]["yaw_prior"] is not None
        doc.pop("wall_time_s")
        return doc

    a, b = once(), once()
    assert a == b
    prior = a["yaw_prior"]
    assert isinstance(prior, float)
    assert prior == pytest.approx(90.0 + math.degrees(yaw_error(5)), abs=0.5)
    assert 0.0 < abs(prior - 90.0) <= 20.5
    assert a["pose"] is not None and a["lost"] is False


def test_an_imu_shift_before_the_ahrs_settles_is_survived_by_re_levelling_from_the_scan(
        ) -> None:
    rigs: list[Rig] = []
    world = world_at(0.8, 2.9, 0.0, seed=2)
    result, oracle = run(world, seed=2, fault="imu-shift", hint="left",
                         rig_hook=rigs.append)  # seed 2: the mount shifts 5.4 deg at 0.53 s
    assert result.fault_info["at_s"] < 1.0
    assert result.relevels == 1 and len(oracle.calls) == 2
    assert result.imu_suspect and "scan" in result.imu_suspect_reason
    assert result.imu_correction_deg == pytest.approx(result.fault_info["deg"], abs=0.5)
    assert not result.lost and len(result.obstacles) == 5
    beam = rigs[0].true_lidar_pose().rotation[:, 0]  # levelled again after the sweep
    assert math.degrees(abs(math.asin(beam[2]))) < 0.4


def test_an_imu_shift_while_parked_is_caught_at_once_and_nothing_is_lost() -> None:
    result, oracle = run(world_at(0.8, 2.9, 0.0, seed=4), seed=4, fault="imu-shift",
                         hint="left")  # seed 4: 7.6 deg at 3.64 s, during the sweep
    assert 2.5 < result.fault_info["at_s"] < 4.0
    assert result.relevels == 0 and result.imu_suspect
    assert "parked" in result.imu_suspect_reason
    assert not result.lost and len(result.obstacles) >= 4


def test_a_localizer_that_is_lost_gets_no_sweep_and_the_json_says_so() -> None:
    world = world_at(0.8, 2.9, 0.0)
    elsewhere = world_at(3.0, 1.0, 0.0)  # the stand-in is told the wrong truth
    result = perceive(world, load_autonomy_config(), localize=OracleLocalizer(elsewhere),
                      detect=OracleDetector(world))
    assert result.lost and result.sweep_records == [] and result.obstacles == []
    doc = result.to_json()
    assert doc["pose"] is None and doc["lost"] is True and doc["obstacles"] == []
    assert doc["true_pose"] == {"x": 0.8, "y": 2.9, "yaw": 0.0}
    assert "walls" in doc["reason"]


@pytest.fixture
def oracles(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """`ramp sim perceive` itself, with the stand-ins in place of the pipeline."""
    real = perceive_module.perceive

    def with_oracles(world: MarteWorld, config: object, **kw: object) -> PerceiveResult:
        return real(world, config, localize=OracleLocalizer(world),  # type: ignore[arg-type]
                    detect=OracleDetector(world), **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(perceive_module, "perceive", with_oracles)
    yield


def test_the_command_prints_the_json_and_draws_the_picture(
        oracles: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "perceive.png"
    code = main(["sim", "perceive", "--world", DEFAULT, "--at", "0.8,2.9,0", "--hint", "left",
                 "--fault", "gyro-drift", "--json", "--plot", str(png)])
    assert code == 0
    doc = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert set(doc["pose"]) == {"x", "y", "yaw", "confidence"}
    assert doc["pose"]["x"] == pytest.approx(0.8) and doc["pose"]["yaw"] == pytest.approx(0.0)
    assert doc["lost"] is False and doc["true_pose"] == {"x": 0.8, "y": 2.9, "yaw": 0.0}
    assert len(doc["obstacles"]) == 5
    assert all(set(o) == {"kind", "x", "y", "d"} and o["kind"] in ("rock", "crater")
               for o in doc["obstacles"])
    assert doc["fault"] == "gyro-drift" and doc["hint"] == "left"
    assert png.stat().st_size > 50_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_the_command_speaks_plainly_without_json(oracles: None,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "perceive", "--seed", "3", "--at", "1.0,1.0,0"]) == 0
    out = capsys.readouterr().out
    assert "estimated pose: x 1.000 y 1.000 yaw 0.0 deg (confidence 0.95)" in out
    assert "true pose:" in out and "obstacles (" in out


@pytest.mark.parametrize("args, message", [
    (["--at", "1,2"], "--at: expected X,Y,YAW"),
    (["--at", "0.1,0.1,0"], "outside the"),
    (["--at", "1,1,0", "--world", "/nonexistent.yaml"], "nonexistent.yaml"),
])
def test_bad_input_exits_2_saying_what_was_expected(args: list[str], message: str,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "perceive", *args]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.skipif(find_spec("ramp.autonomy.perception.localizer") is not None,
                    reason="the localizer is in this build")
def test_without_the_localizer_the_command_says_what_is_missing(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "perceive", "--seed", "1", "--at", "1.0,1.0,0", "--json"]) == 1
    assert "localizer.py) is not in this build yet" in capsys.readouterr().err
