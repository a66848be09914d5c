"""The benchmark suite runs end to end with minimal settings and prints one valid JSON
document with every section; plus the pure parts of its analysis, checked on made-up data."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from bench import SECTIONS
from bench.__main__ import parse_only
from bench.command_to_wire import _match, value_sequence
from bench.common import compare, summary
from bench.realtime import summary_of
from bench.report import render
from bench.tick import window

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def smoke(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("bench") / "bench.json"
    proc = subprocess.run([sys.executable, "-m", "bench", "--smoke", "--out", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=170)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    doc: dict[str, Any] = json.loads(proc.stdout)
    assert json.loads(out.read_text()) == doc
    assert "bench: startup: done" in proc.stderr  # progress on stderr, not in the JSON
    return doc


# The fixture's run: 170 s at most (console_bandwidth adds ~10 s, realtime ~15 s).
@pytest.mark.timeout(180)
def test_every_section_and_the_machine_are_reported(smoke: dict[str, Any]) -> None:
    for name in SECTIONS:
        assert name in smoke and "error" not in smoke[name], smoke.get(name)
    machine = smoke["machine"]
    assert machine["cores"] >= 1 and machine["python"].startswith("CPython")
    assert machine["kernel"] and machine["date"] and machine["cpu_model"]


@pytest.mark.timeout(120)
def test_figures_are_real_measurements_beside_baselines(smoke: dict[str, Any]) -> None:
    tick = smoke["tick"]
    for run in ("idle", "loaded"):
        r = tick[run]
        # Every tick was recorded (a busy neighbour may make the loop skip a few).
        assert r["expected_ticks"] // 2 <= r["ticks"] <= r["expected_ticks"] + 2
        p50 = r["late_us"]["p50"]
        assert p50["value"] > 0 and p50["baseline"] > 0
        assert p50["ratio"] == round(p50["value"] / p50["baseline"], 2)
        assert r["cpu_pct"]["value"] >= 0  # 10 ms resolution: a short run may read 0
    assert tick["loaded"]["load"]["rtt_us"]["n"] > 0

    rt = smoke["round_trip"]
    assert rt["response_bytes"] > 100  # base.get answers all eight rows
    assert rt["sequential"]["rtt_us"]["n"] == smoke["settings"]["rt_requests"]
    for n in smoke["settings"]["tp_clients"]:
        assert rt["pipelined"][f"clients_{n}"]["req_per_s"]["value"] > 0

    tls = smoke["tls"]  # SPEC 13: TLS beside plain on the same server, and a flood
    assert tls["rtt_us"]["p50"]["value"] > 0 and tls["rtt_us"]["p50"]["baseline"] > 0
    assert tls["flood"]["attempts"] > 0
    assert tls["flood"]["operator_connect_to_stop_ms"]["n"] > 0
    assert tls["flood"]["tick_late_us"]["flood"]["n"] > 0

    fleet = smoke["fleet"]  # SPEC 14: Stop all through a real broker, every robot answering
    assert fleet["stop_all_to_driving_false_ms"]["n"] == fleet["robots"] * fleet["rounds"]
    assert all(r["stopped"] == fleet["robots"] for r in fleet["per_round"])

    c2w = smoke["command_to_wire"]
    assert c2w["single"]["missing"] == 0
    assert c2w["single"]["send_to_wire_us"]["p50"]["value"] > 0
    assert 1 <= c2w["driver_max_pending"] <= 4
    for flood in ("flood_one_wheel", "flood_four_wheels"):
        # 1000 commands/s cannot all fit a 9600-baud wire; the relay writes every one.
        assert 0 < c2w[flood]["reached_wire_pct"]["value"] < 100
        assert c2w[flood]["reached_wire_pct"]["baseline"] == 100.0
        assert c2w[flood]["last_command_latency_us"]["n"] >= 1  # the newest value got out

    wd = smoke["watchdog_to_wire"]
    assert wd["missed"] == {"value": 0, "baseline": 0}
    # The supervisor never stops before its timeout, and not long after it.
    assert -1.0 < wd["silent_beyond_timeout_ms"]["p50"]["value"] < 500
    assert 0 <= wd["close_to_zeros_ms"]["p50"]["value"] < 500

    arena = smoke["arena"]
    for key in ("world_step_us", "scan_level_us", "scan_tilted_us",
                "scan_tilted_gimbal_moving_us", "scan_standing_still_us"):
        p50 = arena[key]["p50"]
        assert p50["value"] > 0 and p50["baseline"] > 0 and p50["ratio"] is not None
    assert arena["beams_with_echo"]["tilted"] > 900
    assert arena["mission_world_and_lidar_cpu_s"] > 0
    rc = smoke["recorder"]
    for kind in ("mcp_in", "mcp_out", "health", "module_rows", "command", "event"):
        assert rc["encode"][kind]["ns_per_record"]["p50"]["value"] > 0
    assert rc["encode"]["writer"]["records"] == rc["encode"]["writer"]["of_queued"] > 0
    assert rc["tick"]["on"]["written"] > 0 and rc["tick"]["on"]["ticks"] > 0
    assert rc["tick"]["slow_disk"]["late_us"]["p50"]["baseline"] > 0
    rr = rc["ramp_run"]
    assert rr["off"]["dropped"] is None and rr["on"]["dropped"] is not None
    assert rr["on"]["messages_in_files"] > 0 and rr["on"]["ticks"] > 0
    assert rr["slow_disk"]["late_us"]["p50"]["baseline"] > 0
    assert rr["slow_disk"]["dropped"] is not None

    pc = smoke["perception"]
    for key in ("localize_ms", "detect_ms"):
        assert pc[key]["p50"]["value"] > pc[key]["p50"]["baseline"] > 0
    assert pc["sweep"]["cpu_s"]["p50"]["value"] > pc["sweep"]["cpu_s"]["p50"]["baseline"] > 0
    assert 70 < pc["sweep_scans"] < 100 and pc["sweep"]["simulated_s"]["p50"] > 5.0
    assert pc["flow"]["cpu_s"] > pc["flow"]["detect_cpu_s"] > 0

    rt = smoke["realtime"]
    assert rt["bare"]["processes"] == rt["attached"]["processes"] == 3
    assert rt["attached"]["attached"] and rt["attached"]["backend_service"]["stall_guard"]
    assert rt["attached_default_priority"]["backend_service"]["policy"].startswith("default")
    for mode in ("bare", "attached", "attached_default_priority"):
        assert rt[mode]["ticks"] > 0 and rt[mode]["late_us"]["max"] >= rt[mode]["late_us"]["p50"]
        assert rt[mode]["baseline_late_us"]["p50"] is not None

    st = smoke["startup"]
    assert st["start_to_ready_ms"]["median"]["value"] > st["start_to_ready_ms"]["median"][
        "baseline"] > 0
    assert st["rss_mb_after"]["value"] > st["rss_mb_after"]["baseline"] > 0


def test_summary_uses_nearest_rank_and_compare_gives_ratio() -> None:
    s = summary(range(1000))
    assert (s["n"], s["p50"], s["p99"], s["p99_9"], s["max"]) == (1000, 500, 990, 999, 999)
    assert summary([])["p50"] is None
    assert compare(3.0, 2.0) == {"value": 3.0, "baseline": 2.0, "ratio": 1.5}
    assert compare(1, 0)["ratio"] is None


def test_tick_window_keeps_only_samples_inside_and_counts_overruns() -> None:
    samples = [[0.5, 9.0, 0], [1.0, 10.0, 0], [1.5, 20.0, 1], [2.0, 30.0, 3], [2.5, 99.0, 3]]
    assert window(samples, 1.0, 2.0) == ([10.0, 20.0, 30.0], 3)
    assert window(samples, 5.0, 6.0) == ([], 0)


def test_flood_matching_finds_superseded_refreshed_and_newest_values() -> None:
    ch = (128, 1)
    k = [(128, 0, v) for v in (10, 20, 30, 40)]
    sent = {ch: [(0.000, k[0]), (0.001, k[1]), (0.002, k[2]), (0.003, k[3])]}
    packets = [
        (0.0015, 128, 0, 10),  # command 0, while command 1 is newer: lag 1 ms
        (0.0025, 128, 0, 10),  # the same value again: a refresh, not a new match
        (0.0035, 128, 0, 40),  # command 3, the newest: 1 and 2 were superseded
        (0.0040, 128, 14, 5),  # a timeout packet on the same address: ignored
    ]
    out = _match(packets, sent, 0.0, 0.004, 4)
    assert out["reached_wire_pct"] == 50.0
    assert out["latency_us"]["n"] == 2 and out["latency_us"]["max"] == 1500.0
    assert out["lag_behind_newest_us"]["max"] == 1000.0
    assert out["packets_carrying_newest_pct"] == 50.0
    assert out["last_command_latency_us"]["p50"] == 500.0


def test_value_sequence_never_repeats_the_previous_value() -> None:
    values = [value_sequence(k, 50) for k in range(500)]
    assert all(-100 <= v <= 100 for v in values)
    assert all(a != b for a, b in zip(values, values[1:], strict=False))
    assert len(set(values[:201])) == 201


def test_only_rejects_unknown_names_and_keeps_suite_order() -> None:
    assert parse_only("startup,tick") == ["tick", "startup"]
    with pytest.raises(Exception, match="unknown benchmark nope"):
        parse_only("tick,nope")


@pytest.mark.timeout(120)
def test_report_renders_every_section_as_markdown(smoke: dict[str, Any]) -> None:
    text = render(smoke)
    for name in SECTIONS:
        assert f"**{name}**" in text
    assert "| idle: lateness p50 |" in text and "| start → ready, median |" in text


@pytest.mark.parametrize(("lines", "what"), [
    ([], "the apart mission printed nothing"),
    (["ramp sim mission: running\n"], "the apart mission printed no JSON summary"),
    (['{"outcome": "err\n'], "the apart mission's summary is not JSON"),
])
def test_a_realtime_run_without_a_summary_names_its_mode(lines: list[str], what: str) -> None:
    with pytest.raises(ValueError, match=what):
        summary_of("apart", lines)
    assert summary_of("apart", ['{"outcome": "completed"}\n']) == {"outcome": "completed"}


def test_an_unwritable_out_is_refused_before_any_benchmark(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    bad = tmp_path / "file" / "bench.json"
    proc = subprocess.run([sys.executable, "-m", "bench", "--only", "mission", "--out",
                           str(bad)], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and proc.stdout == ""  # nothing ran: no JSON document
    assert f"--out: cannot write {bad}: Not a directory" in proc.stderr


@pytest.mark.timeout(120)
def test_the_mission_figures_are_medians_and_each_run_is_listed(
        smoke: dict[str, Any]) -> None:
    mission = dict(smoke["mission"])
    assert mission["real_time_factors"] and mission["world_step_factors"]
    mission["real_time_factors"] = [50.3, 58.6, 63.8]
    mission["world_step_factors"] = [333.2, 591.7, 456.9]
    text = render({**smoke, "mission": mission})
    assert ("The medians of 3 runs: real-time factors 50.3, 58.6, 63.8 (`world.step` alone "
            "333.2, 591.7, 456.9).") in text
