"""A supervisor's hold on the mission (the fleet's stopPause, SPEC 14): it stops the robot,
waits in `paused` whoever owns control, and its release resumes as after a takeover; under
an operator's control the release waits for the operator."""

from __future__ import annotations

from tests.unit.mission_world import Script, make_run


def test_a_hold_stops_and_waits_and_its_release_resumes() -> None:
    run = make_run()
    run.run(20.0)
    assert run.mission.has_control
    stops = len(run.world.stops)
    run.mission.hold("stopPause s1")
    run.run(21.0)
    assert run.mission.state == "paused" and "held by a supervisor: stopPause s1" in \
        run.entered("paused")[0].reason
    assert len(run.world.stops) == stops + 1  # the hold stopped what the mission ran
    commands = len(run.world.commands)
    run.run(60.0)  # the autonomy still owns control: the hold keeps it paused
    assert run.mission.state == "paused" and len(run.world.commands) == commands
    run.mission.release_hold()
    run.run(100.0)
    after = run.path[run.path.index("paused") + 1:]
    assert after[:2] == ["acquire_control", "relevel"]
    assert run.mission.held is None and run.mission.has_control


def test_a_released_hold_under_an_operator_waits_for_the_operator() -> None:
    run = make_run(Script(takeovers=((25.0, 60.0),)))
    run.run(20.0)
    run.mission.hold("stopPause")
    run.run(30.0)  # the operator takes over during the hold
    run.mission.release_hold()
    run.run(50.0)
    assert run.mission.state == "paused" and run.world.owner == "operator"
    run.run(100.0)  # the operator released at 60 s
    assert run.path[run.path.index("paused") + 1] == "acquire_control"
    assert run.world.owner == "autonomy"


def test_a_hold_before_the_start_waits_for_the_release() -> None:
    run = make_run(start=False)
    run.mission.hold("waiting for the fleet's order")
    run.mission.start(0.0)
    run.run(30.0)
    assert run.path == ["acquire_control", "paused"]
    run.mission.release_hold()
    run.run(40.0)
    assert run.path[2:4] == ["acquire_control", "initial_localization"]
