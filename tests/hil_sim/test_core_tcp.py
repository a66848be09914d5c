"""The whole supervisor over TCP: framing, limits, watchdog, arbitration, errors (SPEC 2, 2.2)."""

from __future__ import annotations

import pytest

from tests.harness import Harness


@pytest.fixture
def h() -> Harness:
    harness = Harness()
    yield harness
    harness.close()


def test_modules_and_heartbeat(h: Harness) -> None:
    c = h.connect()
    assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(demo,arm)"
    assert c.ask("") == ""  # a heartbeat is answered by a bare newline


def test_fragmented_message_is_accumulated(h: Harness) -> None:
    c = h.connect()
    for piece in ("demo:mo", "tor.vel=(", "40)demo:demo.g", "et=()", "\n"):
        c.send(piece)
        h.pump_io()
    assert c.line() == "demo:motor.vel=(40)demo:lamp.on=(0)"
    assert h.world.motors["demo.motor"] == pytest.approx(0.4)


def test_several_messages_in_one_read_answered_in_order(h: Harness) -> None:
    c = h.connect()
    c.send("demo:motor.vel=(10)\ndemo:demo.get=()\r\n\nrobot:robot.modules=()\n")
    assert c.line() == ""  # actions only: a bare newline
    assert c.line() == "demo:motor.vel=(10)demo:lamp.on=(0)"
    assert c.line() == ""
    assert c.line() == "robot:robot.modules=(demo,arm)"


def test_too_long_line_is_refused_and_stream_resyncs(h: Harness) -> None:
    c = h.connect()
    c.send(b"demo:motor.vel=(" + b"1" * 5000)
    h.pump_io()
    c.send(b")\nrobot:robot.modules=()\n")
    assert c.line().startswith("robot:mcp.error=(too_long,")
    assert c.line() == "robot:robot.modules=(demo,arm)"
    assert h.world.motors.get("demo.motor", 0.0) == 0.0


def test_client_limit_refuses_extra_connection_with_busy(h: Harness) -> None:
    clients = [h.connect() for _ in range(4)]
    extra = h.connect()
    assert extra.line().startswith("robot:mcp.error=(busy,")
    with pytest.raises(ConnectionError):
        extra.line()
    assert clients[0].ask("robot:robot.modules=()") == "robot:robot.modules=(demo,arm)"


def test_bad_request_among_good_ones_changes_nothing_else(h: Harness) -> None:
    c = h.connect()
    resp = c.ask("demo:motor.vel=(20)demo:motor.vel=(300)demo:lamp.on=(1)nope:x.y=()"
                 "demo:motor.spin=()demo:wheel.vel=(1)demo:motor.vel=(nan)")
    assert resp == (
        "demo:motor.error=(bad_params,vel takes one int in -100..100)"
        "nope:x.error=(unknown_module,no module nope; known: robot demo arm)"
        "demo:motor.error=(unknown_function,motor has no function spin)"
        "demo:wheel.error=(unknown_device,demo has no device wheel)"
        "demo:motor.error=(bad_params,vel takes one int in -100..100)")
    assert h.world.motors["demo.motor"] == pytest.approx(0.2)
    assert h.world.outputs["demo.lamp"] is True


def test_syntax_error_ends_the_answer_after_earlier_requests_ran(h: Harness) -> None:
    c = h.connect()
    resp = c.ask("demo:lamp.on=(1)demo:demo.get=()garbage here demo:motor.vel=(50)")
    assert resp.startswith("demo:motor.vel=(0)demo:lamp.on=(1)robot:mcp.error=(syntax,")
    assert h.world.motors.get("demo.motor", 0.0) == 0.0


def test_watchdog_expires_for_silent_commander_while_other_client_polls(h: Harness) -> None:
    driver, monitor = h.connect(), h.connect()
    assert driver.ask("demo:motor.vel=(60)") == ""
    assert "robot:watchdog.state=(armed)" in monitor.ask("robot:robot.get=()")
    for _ in range(8):  # 0.8 s of polling by someone else never feeds it
        h.advance(0.1)
        monitor.ask("demo:demo.get=()")
    assert h.world.motors["demo.motor"] == 0.0
    get = monitor.ask("robot:robot.get=()")
    assert "robot:watchdog.state=(tripped)" in get
    assert monitor.ask("demo:demo.get=()").startswith("demo:motor.vel=(0)")


def test_heartbeats_from_the_commander_keep_it_alive(h: Harness) -> None:
    driver = h.connect()
    driver.ask("demo:motor.vel=(60)")
    for _ in range(20):
        h.advance(0.1)
        assert driver.ask("") == ""
    assert h.world.motors["demo.motor"] == pytest.approx(0.6)
    driver.ask("demo:demo.stop=()")
    assert h.world.motors["demo.motor"] == 0.0
    assert "robot:watchdog.state=(idle)" in driver.ask("robot:robot.get=()")


def test_commander_disconnect_stops_at_once(h: Harness) -> None:
    driver, monitor = h.connect(), h.connect()
    driver.ask("demo:motor.vel=(-70)")
    assert h.world.motors["demo.motor"] == pytest.approx(-0.7)
    driver.close()
    h.pump_io()
    assert h.world.motors["demo.motor"] == 0.0
    assert "robot:watchdog.state=(tripped)" in monitor.ask("robot:robot.get=()")


def test_takeover_by_second_client_stops_motion_first(h: Harness) -> None:
    auto, op = h.connect(), h.connect()
    assert auto.ask("robot:control.acquire=(autonomy)") == ""
    auto.ask("demo:motor.vel=(50)")
    assert op.ask("demo:motor.vel=(10)") == (
        "demo:motor.error=(not_owner,control is held by autonomy)")
    assert op.ask("robot:control.release=()").startswith("robot:control.error=(not_owner,")
    assert op.ask("demo:demo.get=()").startswith("demo:motor.vel=(50)")  # reads are open
    assert op.ask("robot:control.acquire=(operator)") == ""
    assert h.world.motors["demo.motor"] == 0.0  # the new owner starts from rest
    assert auto.ask("demo:motor.vel=(50)").startswith("demo:motor.error=(not_owner,")
    assert op.ask("demo:motor.vel=(15)") == ""
    assert "robot:control.owner=(operator)" in auto.ask("robot:robot.get=()")


def test_stop_is_accepted_from_anyone(h: Harness) -> None:
    owner, other = h.connect(), h.connect()
    owner.ask("robot:control.acquire=(op)")
    owner.ask("demo:motor.vel=(30)")
    assert other.ask("robot:robot.stop=()") == ""
    assert h.world.motors["demo.motor"] == 0.0
    owner.ask("demo:motor.vel=(30)")
    assert other.ask("demo:demo.stop=()") == ""
    assert h.world.motors["demo.motor"] == 0.0


def test_owner_disconnect_releases_control(h: Harness) -> None:
    owner, other = h.connect(), h.connect()
    owner.ask("robot:control.acquire=(op)")
    owner.close()
    h.pump_io()
    assert other.ask("demo:motor.vel=(5)") == ""


def test_watchdog_timeout_request(h: Harness) -> None:
    c = h.connect()
    assert c.ask("robot:watchdog.timeout=(2)") == ""
    assert "robot:watchdog.timeout=(2.0)" in c.ask("robot:robot.get=()")
    for bad in ("0", "-1", "61", "inf", "nan", "x", "", "1e-300", "0.049"):
        resp = c.ask(f"robot:watchdog.timeout=({bad})")
        assert resp == "robot:watchdog.error=(bad_params,timeout takes one float in 0.05..60)"
    assert "robot:watchdog.timeout=(2.0)" in c.ask("robot:robot.get=()")
    assert c.ask("robot:watchdog.timeout=(0.05)") == ""
    assert "robot:watchdog.timeout=(0.05)" in c.ask("robot:robot.get=()")


def test_robot_get_health_rows(h: Harness) -> None:
    c = h.connect()
    h.advance(0.5)
    get = c.ask("robot:robot.get=()")
    for row in ("robot:robot.uptime=(", "robot:tick.rate=(100.0)", "robot:tick.late=(",
                "robot:tick.overruns=(", "robot:watchdog.timeout=(0.5)",
                "robot:watchdog.state=(idle)", "robot:control.owner=(none)",
                "robot:clients.count=(1)", "robot:demo.state=(ok)", "robot:arm.state=(ok)"):
        assert row in get


def test_describe_lists_functions_and_properties(h: Harness) -> None:
    c = h.connect()
    robot = c.ask("robot:robot.describe=()")
    assert "robot:robot.module=(demo)robot:robot.module=(arm)" in robot
    assert "robot:watchdog.function=(timeout,float 0.05..60)" in robot
    assert "robot:control.function=(acquire,name)" in robot
    assert "robot:robot.property=(uptime,float,s)" in robot
    assert "robot:tick.property=(late,int,us)" in robot
    assert "robot:demo.property=(state,name)" in robot
    demo = c.ask("demo:demo.describe=()")
    assert "demo:motor.function=(vel,int -100..100)" in demo
    assert "demo:motor.property=(vel,int,%)" in demo
    assert "demo:lamp.property=(on,int)" in demo


def test_fault_and_reattach_of_one_module(h: Harness) -> None:
    c = h.connect()
    c.ask("arm:motor.vel=(40)")
    h.world.unplugged.add("io2")
    h.advance(0.05)
    assert c.ask("arm:motor.vel=(10)").startswith("arm:motor.error=(fault,module arm is fault")
    assert c.ask("arm:arm.stop=()") == ""  # accepted silently
    assert c.ask("demo:motor.vel=(10)") == ""  # the other module keeps working
    assert "robot:arm.state=(fault)" in c.ask("robot:robot.get=()")
    assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(demo)"
    h.world.unplugged.discard("io2")
    h.advance(1.5)
    assert "robot:arm.state=(ok)" in c.ask("robot:robot.get=()")
    assert h.world.motors["arm.motor"] == 0.0  # re-attached from rest
    assert c.ask("arm:motor.vel=(10)") == ""


def test_module_missing_at_boot_is_detached_then_attaches() -> None:
    from tests.harness import FakeWorld

    world = FakeWorld()
    world.unplugged.add("io2")
    h = Harness(world=world)
    try:
        c = h.connect()
        assert c.ask("arm:motor.vel=(10)").startswith("arm:motor.error=(not_attached,")
        assert c.ask("arm:arm.stop=()") == ""
        world.unplugged.clear()
        h.advance(1.2)
        assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(demo,arm)"
    finally:
        h.close()


def test_garbage_bytes_never_disturb_other_clients(h: Harness) -> None:
    good, bad = h.connect(), h.connect()
    bad.send(b"\x00\xff\xfe((((:::...===)))\n\x80abc\n")
    assert bad.line().startswith("robot:mcp.error=(syntax,")
    assert bad.line().startswith("robot:mcp.error=(syntax,")
    assert good.ask("robot:robot.modules=()") == "robot:robot.modules=(demo,arm)"


def test_shutdown_stops_every_motor(h: Harness) -> None:
    c = h.connect()
    c.ask("demo:motor.vel=(80)arm:motor.vel=(-80)")
    h.sup.shutdown()
    assert h.world.motors["demo.motor"] == 0.0
    assert h.world.motors["arm.motor"] == 0.0
