"""The campaign runner: run assignment, the same rows from local processes, from a Dask
LocalCluster and from calling the mission directly; errors, the table and the JSON report."""

from __future__ import annotations

import argparse
import json
from typing import Any

import pytest

from ramp.simulation.campaign import (
    CampaignError,
    add_parser,
    cli,
    combination,
    load_mission,
    plan_runs,
    run_campaign,
    succeeded,
)
from tests.unit import campaign_missions

PLANNED = "tests.unit.campaign_missions:planned_trip"
CHEAP = "tests.unit.campaign_missions:arithmetic"
BREAKS = "tests.unit.campaign_missions:breaks_on_seed_13"


def direct(mission: Any, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [mission(r["seed"], r["start_box"], r["heading"], r["fault"], 600.0) for r in rows]


def test_runs_take_consecutive_seeds_and_cover_every_box_and_heading() -> None:
    specs = plan_runs(8, seed=5, fault="gyro-drift")
    assert [s.seed for s in specs] == list(range(5, 13))
    assert {(s.start_box, s.heading) for s in specs} == {
        (b, h) for b in ("left", "right") for h in (0, 90, 180, 270)}
    assert all(s.fault == "gyro-drift" and s.duration == 600.0 for s in specs)
    # A run's box and heading follow from its seed alone, whatever the first seed was.
    assert [(s.start_box, s.heading) for s in plan_runs(4, seed=7)] == \
        [combination(s) for s in range(7, 11)]
    with pytest.raises(CampaignError, match="--runs"):
        plan_runs(0)
    with pytest.raises(CampaignError, match="--fault"):
        plan_runs(3, fault="wobble")


def test_local_processes_return_what_the_mission_returns_in_run_order() -> None:
    specs = plan_runs(8, seed=3, mission=PLANNED)
    seen: list[int] = []
    rows = run_campaign(specs, workers=2, on_result=lambda r: seen.append(r["run"]))
    assert [r["run"] for r in rows] == list(range(8)) and sorted(seen) == list(range(8))
    assert [r["summary"] for r in rows] == direct(campaign_missions.planned_trip, rows)
    for r, s in zip(rows, specs, strict=True):
        assert (r["seed"], r["start_box"], r["heading"]) == (s.seed, s.start_box, s.heading)
        assert r["outcome"] == "completed" and r["delivered_kg"] > 0
    assert [succeeded(r) for r in rows] == [
        r["delivered_kg"] >= 10 and r["collisions"] == 0 for r in rows]


@pytest.mark.timeout(90)
def test_a_dask_local_cluster_of_two_processes_gives_the_same_rows() -> None:
    distributed = pytest.importorskip("distributed")
    specs = plan_runs(6, seed=20, mission=CHEAP)
    local = run_campaign(specs, workers=1)
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=":0") as cluster:
        assert len(cluster.workers) == 2
        seen: list[int] = []
        remote = run_campaign(specs, cluster=cluster.scheduler_address,
                              on_result=lambda r: seen.append(r["run"]))
    assert sorted(seen) == list(range(6))
    strip = [{k: v for k, v in r.items() if k != "wall_time_s"} for r in local]
    assert [{k: v for k, v in r.items() if k != "wall_time_s"} for r in remote] == strip


def test_a_crashing_or_silent_run_is_an_error_row_and_the_others_still_run() -> None:
    rows = run_campaign(plan_runs(4, seed=12, mission=BREAKS), workers=2)
    by_seed = {r["seed"]: r for r in rows}
    assert by_seed[13]["outcome"] == "error"
    assert "RuntimeError: simulated crash on seed 13" in by_seed[13]["error"]
    assert by_seed[14]["outcome"] == "error" and "lacks delivered_kg" in by_seed[14]["error"]
    assert by_seed[12]["outcome"] == by_seed[15]["outcome"] == "completed"
    assert not succeeded(by_seed[13])


def test_json_report_is_the_last_line_with_every_run_and_the_success_rate(
        capsys: pytest.CaptureFixture[str]) -> None:
    status = cli(["campaign", "--runs", "8", "--seed", "40", "--workers", "2",
                  "--mission", CHEAP, "--json", "--fault", "imu-shift"])
    assert status == 0
    doc = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    rows = doc["results"]
    assert doc["runs"] == 8 and [r["seed"] for r in rows] == list(range(40, 48))
    expected = direct(campaign_missions.arithmetic, rows)
    assert [r["delivered_kg"] for r in rows] == [e["delivered_kg"] for e in expected]
    ok = sum(e["delivered_kg"] >= 10 and e["collisions"] == 0 for e in expected)
    assert (doc["succeeded"], doc["success_rate"]) == (ok, round(ok / 8, 4))
    assert doc["fault"] == "imu-shift" and all(r["fault"] == "imu-shift" for r in rows)
    assert doc["workers"] == 2 and doc["cluster"] is None


def test_table_names_every_column_and_prints_the_success_rate(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "200")
    status = cli(["campaign", "--runs", "4", "--seed", "12", "--workers", "2",
                  "--mission", BREAKS])
    out, err = capsys.readouterr()
    assert status == 1  # two runs failed with an error
    for column in ("seed", "box", "heading", "fault", "outcome", "delivered kg", "collisions",
                   "crater entries", "losses", "sim time s", "wall time s"):
        assert column in out
    assert "success rate:" in out and "/4 =" in out
    assert "run 1 (seed 13): RuntimeError: simulated crash on seed 13" in err


@pytest.mark.parametrize(("argv", "message"), [
    (["--runs", "3", "--mission", "tests.unit.nothing_here:run"], "cannot import"),
    (["--runs", "3", "--mission", "tests.unit.campaign_missions:nope"], "no function nope"),
    (["--runs", "3", "--mission", "no_colon"], "module:function"),
    (["--runs", "0", "--mission", CHEAP], "--runs: expected 1-100000"),
    (["--runs", "1000000000000", "--mission", CHEAP], "--runs: expected 1-100000"),
    (["--runs", "2", "--seed", "-1", "--mission", CHEAP], "--seed: expected a whole number"),
    (["--runs", "3", "--seed", "4294967294", "--mission", CHEAP], "(with --runs 3)"),
    (["--runs", "2", "--cluster", "tcp://[::1", "--mission", CHEAP], "--cluster 'tcp://[::1'"),
    (["--runs", "2", "--cluster", "tcp://host:99999", "--mission", CHEAP], "--cluster 'tcp://host:99999'"),
    (["--runs", "2", "--duration", "1e308", "--mission", CHEAP], "--duration: expected"),
    (["--runs", "2", "--duration", "nan", "--mission", CHEAP], "--duration: expected"),
    (["--runs", "2", "--cluster", "localhost:8786", "--mission", CHEAP], "tcp://HOST:PORT"),
    (["--runs", "2", "--cluster", "tcp://localhost", "--mission", CHEAP], "no port"),
    (["--runs", "2", "--cluster", "tcp://::1:8786", "--mission", CHEAP], "in brackets"),
    (["--runs", "2", "--workers", "0", "--mission", CHEAP], "--workers"),
])
def test_usage_errors_exit_2_and_say_what_to_fix(argv: list[str], message: str,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["campaign", *argv]) == 2
    assert message in capsys.readouterr().err.replace("\n", " ")


def test_registers_under_the_sim_subcommands() -> None:
    parser = argparse.ArgumentParser(prog="ramp sim")
    add_parser(parser.add_subparsers(dest="cmd"))
    args = parser.parse_args(["campaign", "--runs", "5"])
    assert (args.runs, args.seed, args.fault, args.workers, args.cluster, args.json) == \
        (5, 0, "none", None, None, False)
    assert args.mission == "ramp.simulation.mission:run_mission" and callable(args.func)
    assert load_mission(CHEAP) is campaign_missions.arithmetic


def test_randomize_reaches_every_run_and_the_report() -> None:
    from ramp.simulation.campaign import plan_runs, report, run_one

    mission = "tests.unit.campaign_missions:says_randomized"
    specs = plan_runs(3, 5, mission=mission, randomize=True)
    rows = [run_one(s) for s in specs]
    assert [r["delivered_kg"] for r in rows] == [20.0, 20.0, 20.0]
    assert report(specs, rows, workers=1, cluster=None, wall_time_s=0.0)["randomize"] is True
    plain = plan_runs(1, 5, mission=mission)
    assert run_one(plain[0])["delivered_kg"] == 0.0


def test_a_workers_warnings_stay_out_of_the_campaigns_output() -> None:
    """Spawned workers start with no logging set up; Python's last-resort handler would print
    every run's warnings between the progress bar's lines."""
    import subprocess
    import sys

    code = ("from ramp.simulation.campaign import plan_runs, run_campaign\n"
            "rows = run_campaign(plan_runs(2, seed=1, "
            "mission='tests.unit.campaign_missions:chatty'), workers=1)\n"
            "print(len(rows), rows[0]['outcome'])\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, check=True)
    assert done.stdout.split() == ["2", "completed"]
    assert "interlock" not in done.stderr, done.stderr
