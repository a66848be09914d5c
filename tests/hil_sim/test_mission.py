"""Whole missions: `ramp sim mission` on the backend, every emulator and the autonomy, over
real MCP and SCIP connections on one virtual clock (SPEC 6.3).

- The default run, through the command line: it qualifies, its JSON has SPEC 6.3's fields,
  and its `--trace` refereed on its own (`ramp.simulation.referee`, no code shared with the
  simulator) finds no collision, no crater entry and the delivery at the collector.
- An operator takes control mid-run with a second MCP client: the robot stops and the mission
  pauses; the operator moves the robot and releases control; the mission re-acquires,
  re-localizes and drives on. All of it checked over MCP.
- The same arguments give the same run; bad arguments and world files exit 2.

The whole run takes 15-30 s of wall time (the default mission); the rest a few seconds each.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from ramp.autonomy.mcp_link import McpLink
from ramp.cli import main
from ramp.mcp.session import Reply
from ramp.simulation.campaign import combination
from ramp.simulation.mission import MissionOptions, MissionRun
from ramp.simulation.referee import referee

SUMMARY_FIELDS = ("outcome", "delivered_kg", "sim_time_s", "wall_time_s", "collisions",
                  "crater_entries", "states_visited", "localization_losses", "seed",
                  "start_box", "heading", "fault")


@pytest.mark.timeout(300)
def test_the_default_mission_qualifies_and_its_trace_says_so_on_its_own(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    trace = tmp_path / "run.trace"
    code = main(["sim", "mission", "--json", "--trace", str(trace)])
    out = capsys.readouterr().out.strip().splitlines()
    summary = json.loads(out[-1])
    assert code == 0, out[-12:]
    for name in SUMMARY_FIELDS:
        assert name in summary, name
    assert summary["outcome"] == "completed"
    assert summary["delivered_kg"] >= 10.0
    assert summary["collisions"] == 0 and summary["crater_entries"] == 0
    assert summary["sim_time_s"] <= 600.0 + 5.0
    assert (summary["seed"], summary["start_box"], summary["heading"], summary["fault"]) == (
        0, "left", 0, "none")
    for state in ("acquire_control", "initial_localization", "prepare_for_scan",
                  "scan_for_obstacles", "detect_obstacles", "plan_path_to_dig",
                  "cross_to_dig", "excavate", "plan_path_home", "cross_home", "dock",
                  "deposit", "decouple", "done"):
        assert state in summary["states_visited"], state
    assert any("-> excavate" in line for line in out)  # every state change was printed

    lines = trace.read_text().splitlines()
    header = json.loads(lines[0])
    for key in ("arena", "robot", "rocks", "craters", "start", "seed", "fault"):
        assert key in header, key
    assert header["robot"] == {"length": 1.2, "width": 0.75}
    samples = [json.loads(line) for line in lines[1:]]
    assert set(samples[0]) == {"t", "x", "y", "yaw", "lift", "bin_kg", "delivered_kg", "state"}
    steps = [b["t"] - a["t"] for a, b in zip(samples, samples[1:], strict=False)]
    assert min(steps) == pytest.approx(0.1, abs=1e-6) and max(steps) == pytest.approx(0.1)
    report = referee(trace)
    assert report.collisions == 0 and report.crater_entries == 0
    assert report.delivered_at_collector_kg == pytest.approx(summary["delivered_kg"], abs=0.05)
    assert report.delivered_elsewhere_kg == pytest.approx(0.0, abs=0.01)
    assert report.qualifies
    assert summary["referee"]["collisions"] == 0


class Operator:
    """A second MCP client: takes control while the mission crosses the obstacle area, checks
    over MCP that the robot stopped, drives it back a little, releases control, then watches
    the autonomy take over again and drive."""

    def __init__(self, run: MissionRun) -> None:
        self.run = run
        self.phase = "waiting"
        self.link: McpLink | None = None
        self.t = math.nan
        self.answers: dict[str, dict[str, Any]] = {}
        self.log: list[tuple[str, str]] = []  # (phase, what was seen)

    def ask(self, request: str) -> None:
        assert self.link is not None

        def got(reply: Reply[Any]) -> None:
            rows = {f"{r.device}.{r.prop}": r.values[0] if len(r.values) == 1 else r.values
                    for r in reply.responses()}
            self.answers[request] = rows

        self.link.send(request, got)

    def sampled(self, run: MissionRun, now: float) -> None:
        assert run.autonomy is not None and run.rig is not None
        state = run.autonomy.mission.state
        if self.phase == "waiting" and state == "cross_to_dig":
            self.link = McpLink(run.backend.address, clock=run.rig.clock,  # type: ignore[union-attr]
                                loop=run.rig.scheduler, name="operator")
            run.rig.scheduler.add_task("operator", run.rig.scheduler.rate_hz, self.link.tick)
            self.link.start()
            self.phase, self.t = "connecting", now + 2.0  # let the robot get going first
        elif self.phase == "connecting" and now >= self.t:
            self.link.send("robot:control.acquire=(operator)")  # type: ignore[union-attr]
            self.phase, self.t = "taken", now + 1.0
        elif self.phase == "taken" and now >= self.t:
            self.ask("base:base.get=()")
            self.ask("robot:robot.get=()")
            self.phase, self.t = "checking", now + 0.5
        elif self.phase == "checking" and now >= self.t:
            self.log.append(("paused", state))
            self.answers_paused = dict(self.answers)
            self.link.send("base:base.drive=(30,180)")  # type: ignore[union-attr]
            self.phase, self.t = "driving", now + 2.0  # back 0.15 m: the operator moved it
        elif self.phase == "driving":
            if now < self.t:
                self.link.send("base:base.drive=(30,180)")  # type: ignore[union-attr]
            else:
                self.link.send("base:base.stop=()robot:control.release=()")  # type: ignore
                self.phase, self.t = "released", now
        elif self.phase == "released" and state == "cross_to_dig" and now > self.t + 3.0:
            self.answers.clear()
            self.ask("base:base.get=()")
            self.ask("robot:robot.get=()")
            self.phase, self.t = "resumed", now + 0.5
        elif self.phase == "resumed" and now >= self.t:
            self.log.append(("resumed", state))
            run.request_stop()


@pytest.mark.timeout(180)
def test_an_operator_takeover_pauses_the_mission_and_a_release_resumes_it() -> None:
    box, heading = combination(0)
    run = MissionRun(MissionOptions(seed=0, start_box=box, heading=heading, duration=400))
    op = Operator(run)
    run.observers.append(op)
    try:
        summary = run.run()
    finally:
        if op.link is not None:
            op.link.stop()
    assert op.phase == "resumed", (op.phase, summary)
    paused = op.answers_paused
    base, robot = paused["base:base.get=()"], paused["robot:robot.get=()"]
    assert robot["control.owner"] == "operator"
    assert all(base[f"{w}_wheel.vel"] == 0 for w in ("lf", "lb", "rf", "rb"))
    assert op.log[0] == ("paused", "paused")
    after = op.answers
    assert after["robot:robot.get=()"]["control.owner"] == "autonomy"
    assert any(after["base:base.get=()"][f"{w}_wheel.vel"] != 0 for w in ("lf", "rf"))
    path = [c.dest for c in run.changes]
    i = path.index("paused")
    assert path[i + 1:i + 6] == ["acquire_control", "relevel", "rescan", "relocalize",
                                 "resume"]
    assert "cross_to_dig" in path[i + 6:]
    assert summary["collisions"] == 0 and summary["crater_entries"] == 0
    # the pause is announced once, saying who holds control
    assert path.count("paused") == 1
    line = next(c for c in run.changes if c.dest == "paused")
    assert "operator" in line.reason


def test_the_same_arguments_give_the_same_run() -> None:
    def once() -> dict[str, Any]:
        box, heading = combination(3)
        s = MissionRun(MissionOptions(seed=3, start_box=box, heading=heading,
                                      duration=45.0)).run()
        return {k: v for k, v in s.items() if k not in ("wall_time_s", "rtf")}

    first, second = once(), once()
    assert first == second
    assert "scan_for_obstacles" in first["states_visited"]


@pytest.mark.parametrize("args, message", [
    (["--heading", "45"], "invalid choice"),
    (["--start-box", "middle"], "invalid choice"),
    (["--duration", "-5"], "--duration: expected a positive number"),
    (["--duration", "1e308"], "--duration: expected a positive number"),
    (["--seed", "-1"], "--seed: expected a whole number"),
    (["--port", "5577"], "--port: only with --realtime"),
    (["--single-loop"], "--single-loop: only with --realtime"),
    (["--fault", "wobble"], "invalid choice"),
])
def test_bad_arguments_exit_2_saying_what_was_expected(
        args: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    try:
        code = main(["sim", "mission", *args])
    except SystemExit as exc:  # argparse's own usage errors
        code = int(exc.code or 0)
    assert code == 2
    assert message in capsys.readouterr().err


def test_a_bad_world_file_exits_2_naming_its_line(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    world = tmp_path / "w.yaml"
    world.write_text("rocks:\n  - {x: 2.0, y: 1.0, d: -0.2}\n")
    assert main(["sim", "mission", "--world", str(world)]) == 2
    err = capsys.readouterr().err
    assert "w.yaml:2: rocks[0].d:" in err


class DriveWatch:
    """Every 0.1 s: is the mission's pose confident, and is any wheel commanded? Stops the
    run a minute after the robot first drives once the IMU's mount has shifted (a shift
    during a dig is found when the robot stands to localize on the way home)."""

    def __init__(self) -> None:
        self.driving_unsure: list[float] = []  # times a wheel turned with no confident pose
        self.unsure_since: float | None = None
        self.shift_at = math.nan
        self.drove_after_shift: float | None = None

    def started(self, run: MissionRun) -> None:
        assert run.rig is not None
        self.shift_at = run.rig.imu_emulator.fault_info()["at_s"]

    def sampled(self, run: MissionRun, now: float) -> None:
        assert run.autonomy is not None
        mission = run.autonomy.mission
        moving = any(run.world.duty(f"base.{w}_wheel") != 0.0 for w in ("lf", "lb", "rf",
                                                                        "rb"))
        sure = mission.pose_confident()
        if sure:
            self.unsure_since = None
        elif self.unsure_since is None:
            self.unsure_since = now
        # one mission tick (0.05 s) plus the stop's way to the wheels may pass first
        if moving and self.unsure_since is not None and now - self.unsure_since > 0.25:
            self.driving_unsure.append(run.mission_time(now))
        t = run.mission_time(now)
        if moving and mission.state != "excavate" and t > self.shift_at \
                and self.drove_after_shift is None:  # driving, not the dig's creep
            self.drove_after_shift = t
        if self.drove_after_shift is not None and t > self.drove_after_shift + 60.0:
            run.request_stop()


@pytest.mark.timeout(180)
def test_an_imu_shift_while_driving_is_levelled_out_and_never_driven_through_blind() -> None:
    box, heading = combination(0)
    run = MissionRun(MissionOptions(seed=0, start_box=box, heading=heading, fault="imu-shift",
                                    duration=600.0))
    watch = DriveWatch()
    run.observers.append(watch)
    summary = run.run()
    assert 60.0 <= watch.shift_at <= 540.0
    assert watch.drove_after_shift is not None
    assert run.mission_time(run.ended_at) > watch.drove_after_shift + 60.0
    assert watch.driving_unsure == []
    assert summary["collisions"] == 0 and summary["crater_entries"] == 0
    assert run.autonomy is not None
    ahrs = run.autonomy.kit.perception.ahrs
    assert ahrs.correction_deg > 3.0  # the shift found its way into the mount correction
    assert run.autonomy.mission.state not in ("waiting_for_operator", "paused")
