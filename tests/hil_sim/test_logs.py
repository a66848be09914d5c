"""One log line per event an operator cares about, naming who and what (issue 4, logs)."""

from __future__ import annotations

import logging

import pytest

from ramp.clock import VirtualClock
from ramp.scheduler import Scheduler
from tests.harness import Harness


@pytest.fixture
def h() -> Harness:
    harness = Harness()
    yield harness
    harness.close()


def lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records]


def test_control_changes_are_logged(h: Harness, caplog: pytest.LogCaptureFixture) -> None:
    a, b = h.connect(), h.connect()
    with caplog.at_level(logging.INFO):
        a.ask("robot:control.acquire=(autonomy)")
        b.ask("robot:control.acquire=(operator)")
        b.ask("robot:control.release=()")
    text = "\n".join(lines(caplog))
    assert "control acquired by autonomy (127.0.0.1:" in text
    assert "control taken over: autonomy -> operator (127.0.0.1:" in text
    assert "control released by operator (127.0.0.1:" in text


def test_watchdog_trip_names_the_client(h: Harness, caplog: pytest.LogCaptureFixture) -> None:
    c = h.connect()
    c.ask("demo:motor.vel=(30)")
    peer = next(iter(h.sup.server.clients.values())).peer
    with caplog.at_level(logging.WARNING):
        h.advance(0.7)
    assert any(f"watchdog expired: {peer} silent" in m for m in lines(caplog))
    c.ask("demo:motor.vel=(30)")
    with caplog.at_level(logging.WARNING):
        c.close()
        h.pump_io()
    assert any(f"commanding client {peer} disconnected" in m for m in lines(caplog))


def test_module_state_changes_are_logged(h: Harness, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO):
        h.world.unplugged.add("io2")
        h.advance(0.05)
        h.world.unplugged.clear()
        h.advance(1.2)
    text = "\n".join(lines(caplog))
    assert "bus io2 fault: simulated device unplugged" in text
    assert "module arm fault: bus io2: simulated device unplugged; its motion is stopped" in text
    assert "bus io2 is back" in text
    assert "module arm re-attached" in text


def test_overrun_warnings_are_throttled_and_name_the_task(
        caplog: pytest.LogCaptureFixture) -> None:
    clock = VirtualClock()
    s = Scheduler(clock, 100, overrun_log_interval=1e9)
    s.add_task("slow_filter", 100, lambda now, dt: clock.advance(0.025))
    with caplog.at_level(logging.WARNING, logger="ramp.scheduler"):
        s.run_for(1.0)
    warnings = [m for m in lines(caplog) if "tick overrun" in m]
    assert s.stats.overruns > 10
    assert len(warnings) == 1  # throttled
    assert "slowest task slow_filter (25.0 ms)" in warnings[0]


def test_logs_have_no_colour_codes_off_a_terminal(capfd: pytest.CaptureFixture[str]) -> None:
    from ramp.cli import setup_logging

    root = logging.getLogger()
    saved, level = root.handlers[:], root.level
    try:
        setup_logging("info")
        logging.getLogger("ramp.test").warning("one line")
        err = capfd.readouterr().err
    finally:
        root.handlers[:] = saved
        root.setLevel(level)
    assert err == "WARNING ramp.test: one line\n"


def test_journald_gets_syslog_priorities(capfd: pytest.CaptureFixture[str],
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from ramp.cli import setup_logging

    monkeypatch.setenv("JOURNAL_STREAM", "8:12345")
    root = logging.getLogger()
    saved, level = root.handlers[:], root.level
    try:
        setup_logging("info")
        logging.getLogger("ramp.test").warning("low battery")
        logging.getLogger("ramp.test").error("bus gone")
        err = capfd.readouterr().err
    finally:
        root.handlers[:] = saved
        root.setLevel(level)
    assert err == "<4>WARNING ramp.test: low battery\n<3>ERROR ramp.test: bus gone\n"
