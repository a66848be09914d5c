"""The mission state machine driven by small real activities in a scripted world
(`mission_world.py`), on virtual time: the whole cycle, the end of the run, every recovery,
the bounded retries, the operator, exceptions, and never driving while lost."""

from __future__ import annotations

import logging

import pytest

from ramp.statemachine import Executive, Mission, MissionError, Status
from ramp.statemachine.mission import LOCALIZATION
from ramp.statemachine.table import DRIVING
from tests.unit.mission_world import Run, Script, make_run

CYCLE = ["plan_path_to_dig", "cross_to_dig", "excavate", "plan_path_home", "cross_home", "dock",
         "deposit", "decouple"]
RECOVERY = ["stop", "relevel", "rescan", "relocalize", "resume"]


def _after(run: Run, state: str, index: int = 0) -> list[str]:
    """The states entered after the `index`-th entry into `state`."""
    positions = [i for i, s in enumerate(run.path) if s == state]
    return run.path[positions[index] + 1:]


def _never_drove_while_lost(run: Run) -> None:
    assert run.world.drove_while_lost == []
    for change in run.changes:
        if change.dest in DRIVING:
            assert not change.trigger.startswith("lost")


# -- the whole run ---------------------------------------------------------------------------------
def test_a_run_follows_figure_5_35_and_cycles_until_the_time_is_nearly_out(
        caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="ramp.statemachine")
    run = make_run().run(700)
    assert run.path[:5] == ["acquire_control", "initial_localization", "prepare_for_scan",
                            "scan_for_obstacles", "detect_obstacles"]
    assert run.path[5:5 + 2 * len(CYCLE)] == CYCLE + CYCLE
    ctx, world = run.mission.context, run.world
    assert run.mission.state == "done" and run.mission.outcome == "completed"
    assert ctx.deposits >= 5 and ctx.delivered_kg == pytest.approx(world.delivered_kg)
    assert world.delivered_kg >= 40.0
    # the last cycle ended at the collector with an empty bin, before the run's time was out
    assert run.changes[-1].source == "decouple" and "no time for another cycle" in \
        run.changes[-1].reason
    assert world.t < ctx.budget.end_s and world.bin_kg < 0.05
    # no spot dug twice; the robot stopped at the end and nowhere else
    ys = [spot.pose.y for spot in ctx.dig_spots_done]
    # (the last load may come home before its dig finished: the time left sent it home)
    assert ctx.deposits - 1 <= len(ys) <= ctx.deposits and len(set(ys[:4])) == 4
    home_early = [c.t for c in run.changes if c.trigger == "head_home"]  # the dig stopped
    assert world.stops == sorted(home_early + [world.t])
    _never_drove_while_lost(run)
    # one log line per change, in the promised format
    lines = [r.getMessage() for r in caplog.records if r.name == "ramp.statemachine"]
    assert lines == [c.line() for c in run.changes]
    assert lines[6] == "mission: plan_path_to_dig -> cross_to_dig (finished: to (5.2, 1.2))"


def test_the_machine_measures_its_legs_for_the_end_decisions() -> None:
    run = make_run().run(300)
    est = run.mission.context.estimates
    # configured guesses of 60 s come down towards what the world takes (about 16 s a trip,
    # under 10 s at the collector), halfway per measurement, never below one
    assert 16.0 < est.trip_s < 30.0 and 5.0 < est.dock_deposit_s < 20.0
    assert 16.0 < est.home_s < 30.0  # the way home is measured on its own


def test_until_the_way_home_is_driven_it_is_taken_as_long_as_the_way_out() -> None:
    """The first dig is sized with a way home: the guess (60 s) was 30 s short on a slow
    layout, so the measured way out stands in for it until home has been driven once."""
    run = make_run()
    seen: list[tuple[str, float, float]] = []
    est = run.mission.context.estimates
    run.mission.add_listener(lambda c: seen.append((c.dest, est.trip_s, est.home_s)))
    run.run(300)
    at_dig = next((trip, home) for dest, trip, home in seen if dest == "excavate")
    assert at_dig[0] < 60.0 and at_dig[1] == at_dig[0]
    # from the first dock on, the way home is its own measurement (here shorter than out)
    after_dock = [(trip, home) for dest, trip, home in seen if dest == "deposit"]
    assert after_dock and after_dock[0][1] != after_dock[0][0]


def test_near_the_end_a_loaded_robot_heads_home_and_delivers_its_last_load() -> None:
    run = make_run(Script(target_kg=1000.0), duration_s=300)  # digs until told
    ctx = run.mission.context
    return_s: list[float] = []
    run.mission.add_listener(lambda c: return_s.append(ctx.estimates.return_s()))
    run.run(400)
    heading_home = [c for c in run.changes if c.trigger == "head_home"]
    assert len(heading_home) == 1 and heading_home[0].source == "excavate"
    assert "kg in the bin" in heading_home[0].reason
    turn = heading_home[0].t
    needed = return_s[run.changes.index(heading_home[0])]
    # it left with time for the return and the margin, and not a tick earlier than it had to
    assert needed - 0.1 < ctx.budget.left(turn) - ctx.budget.margin_s <= needed
    assert _after(run, "excavate")[:6] == ["plan_path_home", "cross_home", "dock", "deposit",
                                           "decouple", "done"]
    assert run.world.delivered_kg > 5.0 and run.world.t < ctx.budget.end_s


@pytest.mark.parametrize(("script", "config"), [
    (Script(dig_kg_s=0.0, target_kg=1000.0), {}),  # nothing in the bin
    (Script(dig_kg_s=0.01, target_kg=1000.0), {"min_return_load_kg": 5.0}),  # too little
])
def test_a_last_return_that_does_not_pay_ends_the_run_where_it_is(
        script: Script, config: dict[str, float]) -> None:
    run = make_run(script, duration_s=300, **config).run(400)
    last = run.changes[-1]
    assert (last.source, last.dest, last.trigger) == ("excavate", "done", "time_up")
    assert "does not pay" in last.reason
    assert run.world.stops == [last.t] and run.world.speed == 0 and not run.world.chain


def test_a_return_that_no_longer_fits_in_the_time_left_is_not_started() -> None:
    # the operator holds the robot past the point of return; it comes back loaded, too late
    run = make_run(Script(target_kg=1000.0, takeovers=((80.0, 260.0),)), duration_s=300)
    run.run(400)
    last = run.changes[-1]
    assert last.trigger == "time_up" and "does not pay" in last.reason
    assert run.mission.context.bin_kg > 5.0 and run.world.delivered_kg == 0.0


def test_the_end_of_the_run_ends_any_state() -> None:
    run = make_run(Script(stuck={"scan_for_obstacles"}), duration_s=20,
                   timeout_scan_for_obstacles_s=60).run(30)
    assert run.changes[-1].source == "scan_for_obstacles"
    assert run.changes[-1].reason == "time_up: the run's time is over"
    assert run.changes[-1].t == pytest.approx(20.0)


# -- recovery ----------------------------------------------------------------------------------
def test_a_lost_pose_while_crossing_stops_relevels_rescans_relocalizes_and_plans_again() -> None:
    run = make_run(Script(lose_pose_at=(12.0,))).run(150)
    lost = run.entered("stop")[0]
    assert lost.source == "cross_to_dig" and lost.trigger == "lost"
    assert lost.reason == "lost: pose confidence 0.20 < 0.5"
    assert _after(run, "stop")[:7] == ["relevel", "rescan", "relocalize", "resume",
                                       "plan_path_to_dig", "cross_to_dig", "excavate"]
    assert run.world.stops[0] == lost.t  # stopped on the spot
    assert run.mission.context.localization_losses == 1
    assert run.mission.context.deposits >= 1
    _never_drove_while_lost(run)


def test_each_change_says_the_localization_from_the_machine_s_own_bookkeeping() -> None:
    """Issue 35: the console read "lost" from a reason's wording; the change carries it."""
    run = make_run(Script(lose_pose_at=(12.0,))).run(150)
    by_dest = [(c.dest, c.localization) for c in run.changes]
    assert by_dest[0] == ("acquire_control", "none")
    assert ("prepare_for_scan", "ok") in by_dest
    i = by_dest.index(("stop", "lost"))
    assert by_dest[i + 1:i + 4] == [("relevel", "lost"), ("rescan", "lost"),
                                    ("relocalize", "lost")]
    assert by_dest[i + 4] == ("resume", "ok")
    assert all(loc in LOCALIZATION for _, loc in by_dest)


def test_relocalizing_after_a_takeover_is_not_being_lost() -> None:
    run = make_run(Script(takeovers=((30.0, 50.0),))).run(120.0)
    after = [(c.dest, c.localization) for c in run.changes if c.t >= 50.0][:5]
    assert after[1:4] == [("relevel", "relocalizing"), ("rescan", "relocalizing"),
                          ("relocalize", "relocalizing")], after


def test_it_never_enters_a_driving_state_without_a_confident_pose() -> None:
    run = make_run(Script(lose_pose_finishing={"plan_path_to_dig": 1})).run(60)
    first = run.changes[6]
    assert (first.source, first.dest, first.trigger) == ("plan_path_to_dig", "stop", "finished")
    assert "pose confidence 0.20" in first.reason
    assert _after(run, "stop")[:6] == ["relevel", "rescan", "relocalize", "resume",
                                       "plan_path_to_dig", "cross_to_dig"]
    _never_drove_while_lost(run)


def test_a_pose_lost_again_and_again_before_driving_ends_waiting_for_the_operator() -> None:
    run = make_run(Script(lose_pose_finishing={"plan_path_to_dig": 99})).run(200)
    assert run.mission.state == "waiting_for_operator"
    assert len(run.entered("relocalize")) == 3 and "cross_to_dig" not in run.path
    _never_drove_while_lost(run)


def test_relocalization_is_tried_a_bounded_number_of_times_then_waits_for_the_operator() -> None:
    run = make_run(Script(lose_pose_at=(12.0,), relocalize_failures=99),
                   max_relocalize_tries=2).run(700)
    assert run.mission.state == "waiting_for_operator"
    assert run.mission.outcome == "waiting_for_operator"
    assert _after(run, "stop") == ["relevel", "rescan", "relocalize", "stop",
                                   "relevel", "rescan", "relocalize", "stop",
                                   "waiting_for_operator"]
    assert run.changes[-1].reason == "still lost after 2 relocalization tries"
    moving_after_loss = [c for c in run.world.commands if c[0] >= 12.0]
    assert moving_after_loss == []
    assert run.world.stops[-1] == run.changes[-1].t
    # it waits there past the end of the run, and past losing control: only an operator
    # taking over ends this
    assert run.world.t == pytest.approx(700.0)
    run.world.owner = "none"
    run.run(710.0)
    assert run.mission.state == "waiting_for_operator"


def test_a_relocalization_that_succeeds_on_a_later_try_resumes_the_task() -> None:
    run = make_run(Script(lose_pose_at=(12.0,), relocalize_failures=2)).run(120)
    assert _after(run, "stop")[:8] == ["relevel", "rescan", "relocalize", "stop", "relevel",
                                       "rescan", "relocalize", "stop"]
    assert _after(run, "stop", 2)[:5] == ["relevel", "rescan", "relocalize", "resume",
                                          "plan_path_to_dig"]
    assert run.mission.context.localization_losses == 1


def test_a_fault_stops_the_robot_and_retries_the_step() -> None:
    run = make_run(Script(faults={"excavate": 1})).run(120)
    stop = run.entered("stop")[0]
    assert (stop.source, stop.trigger) == ("excavate", "fault")
    assert stop.reason == "fault: fault: ble:chain.vel"
    assert _after(run, "stop")[:4] == ["resume", "plan_path_to_dig", "cross_to_dig",
                                       "excavate"]
    assert run.mission.context.faults == 1 and run.mission.context.localization_losses == 0
    assert run.world.stops[0] == stop.t
    assert run.mission.context.deposits >= 1


@pytest.mark.parametrize("kind", ["faults", "failures"])
def test_a_step_that_keeps_failing_is_retried_a_bounded_number_of_times(kind: str) -> None:
    script = Script(**{kind: {"deposit": 99}})
    run = make_run(script, max_step_retries=2).run(300)
    assert run.mission.state == "waiting_for_operator"
    tries = [c for c in run.changes if c.dest == "deposit"]
    assert len(tries) == 3  # the first, then 2 retries
    assert _after(run, "stop", 2) == ["waiting_for_operator"]
    assert run.changes[-1].reason.startswith("still failing after 2 retries")


def test_a_retried_step_that_finishes_earns_fresh_retries_for_later_ones() -> None:
    run = make_run(Script(faults={"cross_to_dig": 2, "cross_home": 2}),
                   max_step_retries=2).run(200)
    assert "waiting_for_operator" not in run.path
    assert run.mission.context.faults == 4 and run.mission.context.deposits >= 1


def test_a_fault_reported_by_the_link_stops_and_retries_the_step() -> None:
    run = make_run()
    run.run(25.0)
    assert run.mission.state == "excavate"
    run.mission.report_fault("watchdog tripped")
    run.run(26.0)
    stop = run.entered("stop")[0]
    assert (stop.source, stop.reason) == ("excavate", "fault: watchdog tripped")
    run.run(40.0)
    assert "excavate" in _after(run, "stop")


def test_a_state_that_never_finishes_times_out_as_a_failure() -> None:
    run = make_run(Script(stuck={"detect_obstacles"}), timeout_detect_obstacles_s=4,
                   max_step_retries=1).run(100)
    failures = [c for c in run.changes if c.trigger == "failed"]
    assert [c.reason for c in failures] == ["failed: no result after 4 s"] * 2
    assert run.mission.state == "waiting_for_operator"


# -- the operator ---------------------------------------------------------------------------------
@pytest.mark.parametrize(("takeover", "poll_every", "paused_from", "seen_by"), [
    # crossing: the next drive command answers not_owner before the link polls
    (14.0, 50, "cross_to_dig", "not_owner"),
    # scanning sends nothing; the link's robot.get shows another owner
    (5.0, 5, "scan_for_obstacles", "operator took control"),
])
def test_an_operator_takeover_pauses_and_a_release_resumes_after_relocalizing(
        takeover: float, poll_every: int, paused_from: str, seen_by: str,
        caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="ramp.statemachine")
    run = make_run(Script(takeovers=((takeover, takeover + 20.0),)))
    run.run(takeover + 10.0, poll_every=poll_every)
    pause = run.entered("paused")[0]
    assert pause.source == paused_from and seen_by in pause.reason
    assert run.mission.state == "paused" and not run.mission.has_control
    # nothing was commanded from the takeover on, not even a stop: the motion is the operator's
    assert [c for c in run.world.commands if c[0] >= takeover] == []
    assert [t for t in run.world.stops if t >= takeover] == []
    announced = [r for r in caplog.records if "-> paused" in r.getMessage()]
    assert len(announced) == 1 and announced[0].levelno == logging.WARNING
    run.run(200.0, poll_every=poll_every)
    assert _after(run, "paused")[:5] == ["acquire_control", "relevel", "rescan", "relocalize",
                                         "resume"]
    resumed = run.path[run.path.index("resume") + 1]
    assert resumed == {"cross_to_dig": "plan_path_to_dig",
                       "scan_for_obstacles": "prepare_for_scan"}[paused_from]
    assert run.world.owner == "autonomy" and run.mission.has_control
    assert run.mission.context.deposits >= 1
    _never_drove_while_lost(run)


def test_only_a_free_control_ends_a_pause() -> None:
    run = make_run(Script(takeovers=((14.0, 1000.0),)))
    run.run(30.0, poll_every=1000)
    assert run.mission.state == "paused"
    run.mission.observe_control("autonomy")  # an answer read late still names the mission
    run.run(40.0, poll_every=1000)
    assert run.mission.state == "paused" and run.world.owner == "operator"
    run.world.owner = "none"  # the operator releases
    run.mission.observe_control("none")
    run.run(41.0, poll_every=1000)
    assert _after(run, "paused")[:2] == ["acquire_control", "relevel"]


def test_control_given_up_while_the_mission_holds_it_is_taken_back() -> None:
    run = make_run()
    run.run(20.0)
    run.world.owner = "none"  # the backend forgot us (a reconnect)
    run.run(40.0)
    assert _after(run, "paused")[:2] == ["acquire_control", "relevel"]
    assert "given up" in run.entered("paused")[0].reason


def test_an_operator_can_take_over_from_a_robot_waiting_for_them_and_hand_it_back() -> None:
    run = make_run(Script(lose_pose_at=(12.0,), relocalize_failures=2, takeovers=((60, 70),)),
                   max_relocalize_tries=2)
    run.run(59.0)
    assert run.mission.state == "waiting_for_operator"
    run.run(200.0)
    assert _after(run, "waiting_for_operator")[:6] == [
        "paused", "acquire_control", "relevel", "rescan", "relocalize", "resume"]
    assert _after(run, "resume", -1)[0] == "plan_path_to_dig"  # the interrupted crossing
    assert run.mission.context.deposits >= 1


def test_a_robot_someone_else_controls_at_the_start_waits_for_control() -> None:
    run = make_run(start=False)
    run.world.owner = "operator"
    run.mission.start(0.0)
    run.run(5.0)
    assert run.path == ["acquire_control", "paused"]
    run.world.owner = "none"
    run.run(10.0)
    assert run.path[2:4] == ["acquire_control", "initial_localization"]


# -- exceptions --------------------------------------------------------------------------------
@pytest.mark.parametrize("where", ["start", "tick"])
def test_an_activity_that_raises_stops_the_robot_and_is_retried(
        where: str, caplog: pytest.LogCaptureFixture) -> None:
    run = make_run(Script(raises={"excavate": (where, 1)}))
    stops_when_announced: dict[int, int] = {}
    run.mission.add_listener(
        lambda c: stops_when_announced.setdefault(id(c), len(run.world.stops)))
    run.run(120)
    stop = run.entered("stop")[0]
    # on_exception stopped the robot before the machine even left excavate
    assert stops_when_announced[id(stop)] == 1
    assert stop.source == "excavate" and stop.trigger == "fault"
    assert "RuntimeError in excavate" in stop.reason and f"excavate {where} broke" in stop.reason
    assert run.world.stops[0] == stop.t
    assert any(r.levelno == logging.ERROR and r.exc_info for r in caplog.records)
    assert "excavate" in _after(run, "stop") and run.mission.context.deposits >= 1


def test_an_activity_that_always_raises_ends_waiting_for_the_operator() -> None:
    run = make_run(Script(raises={"deposit": ("start", 99)}), max_step_retries=2).run(300)
    assert run.mission.state == "waiting_for_operator"
    assert len(run.entered("deposit")) == 3
    assert run.world.stops[-1] == run.changes[-1].t


def test_on_exception_stops_the_robot_when_a_stop_activity_breaks() -> None:
    world_run = make_run(start=False)
    mission = world_run.mission

    class BrokenStop:
        def start(self, ctx: object, now: float) -> None:
            raise OSError("stop activity broke")

        def tick(self, now: float, dt: float) -> Status:
            return Status.running()

        def stop(self) -> None:
            pass

    mission.executive.register("stop", BrokenStop)  # type: ignore[arg-type]
    mission.start(0.0)
    world_run.world.script.faults["cross_to_dig"] = 1
    world_run.run(60)
    assert world_run.path[-3:] == ["cross_to_dig", "stop", "waiting_for_operator"]
    assert len(world_run.world.stops) == 3  # entering stop, on_exception, entering waiting


def test_a_listener_that_raises_does_not_stop_the_mission() -> None:
    run = make_run(start=False)

    def broken(change: object) -> None:
        raise ValueError("listener broke")

    run.mission.add_listener(broken)
    run.mission.start(0.0)
    run.run(60)
    assert run.mission.context.deposits == 0 and "excavate" in run.path
    assert run.world.stops == []


# -- use ------------------------------------------------------------------------------------
def test_start_names_the_states_without_an_activity_and_starts_once() -> None:
    mission = Mission(Executive({"dock": lambda: None}), lambda: None)  # type: ignore[dict-item]
    with pytest.raises(MissionError, match="no activity registered for: acquire_control, "
                       "initial_localization"):
        mission.start(0.0)
    run = make_run()
    with pytest.raises(MissionError, match="already started"):
        run.mission.start(1.0)


def test_the_executive_refuses_names_that_are_not_working_states() -> None:
    with pytest.raises(ValueError, match="no working state named 'paused'"):
        Executive({"paused": lambda: None})  # type: ignore[dict-item]
    with pytest.raises(TypeError, match="must be a factory"):
        Executive().register("dock", object())  # type: ignore[arg-type]


def test_a_tick_that_returns_no_status_is_a_fault() -> None:
    run = make_run(start=False)

    class Silent:
        def start(self, ctx: object, now: float) -> None: ...

        def tick(self, now: float, dt: float) -> None: ...

        def stop(self) -> None: ...

    run.mission.executive.register("prepare_for_scan", Silent)  # type: ignore[arg-type]
    run.mission.start(0.0)
    run.run(4.0)
    assert run.entered("stop")[0].source == "prepare_for_scan"
    assert "not a Status" in run.entered("stop")[0].reason


def test_statuses_map_to_triggers_and_mcp_errors() -> None:
    assert Status.running().trigger is None and Status.done().trigger == "finished"
    assert Status.from_mcp_error("not_owner", "operator holds control").trigger == \
        "control_taken"
    assert Status.from_mcp_error("interlocked", "lift raised").trigger == "control_taken"
    assert Status.needs_operator("lift stalled").trigger == "needs_operator"
    fault = Status.from_mcp_error("not_attached", "ble")
    assert fault.trigger == "fault" and fault.reason == "not_attached: ble"
    with pytest.raises(ValueError, match="says why"):
        Status.lost("")
    assert str(Status.failed("no path")) == "failed(no path)"
