"""Idle ticks: while the owner says nothing moves, the scheduler wakes every `idle_stride` base
periods; tasks keep their grid and see the real dt; `hurry` brings the next base slot back."""

from __future__ import annotations

import socket
import threading
import time

import pytest

from ramp.clock import MonotonicClock, VirtualClock
from ramp.scheduler import Scheduler


def recorder(s: Scheduler, name: str, rate: float) -> list[tuple[float, float]]:
    seen: list[tuple[float, float]] = []
    s.add_task(name, rate, lambda now, dt: seen.append((now, dt)))
    return seen


@pytest.mark.parametrize(("rate", "idle", "stall", "stride"), [
    (100, None, 0.25, 1), (100, 100, 0.25, 1), (100, 20, 0.25, 5), (100, 30, 0.25, 3),
    (100, 1, 0.25, 12), (100, 1, 0.04, 2), (100, 200, 0.25, 1), (50, 20, 0.25, 2),
])
def test_the_stride_is_whole_base_periods_and_never_reaches_half_the_stall_limit(
        rate: float, idle: float | None, stall: float, stride: int) -> None:
    s = Scheduler(VirtualClock(), rate, stall_limit=stall, idle_rate_hz=idle)
    assert s.idle_stride == stride
    assert stride * s.period <= max(s.stall_limit / 2, s.period) + 1e-12


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_an_idle_rate_that_is_no_rate_is_refused(bad: float) -> None:
    with pytest.raises(ValueError, match="idle tick rate"):
        Scheduler(VirtualClock(), 100, idle_rate_hz=bad)


def test_while_idle_tasks_run_at_the_idle_rate_on_their_grid_with_the_real_dt() -> None:
    s = Scheduler(VirtualClock(), 100, idle_rate_hz=20)
    s.idle = lambda: True
    fast, ten, one = recorder(s, "fast", 100), recorder(s, "ten", 10), recorder(s, "one", 1)
    s.run_for(2.0)
    assert len(fast) == 40
    assert all(dt == pytest.approx(0.05) for _, dt in fast[1:])
    assert len(ten) == 20 and all(dt == pytest.approx(0.1) for _, dt in ten[1:])
    assert len(one) == 2
    assert s.stats.overruns == 0 and s.stats.skipped == 0
    assert s.stats.percentiles()[2] == 0.0  # an idle tick is on time, not 40 ms late


def test_not_idle_is_every_base_tick_and_the_rate_follows_the_predicate() -> None:
    s = Scheduler(VirtualClock(), 100, idle_rate_hz=20)
    idle = {"now": False}
    s.idle = lambda: idle["now"]
    fast = recorder(s, "fast", 100)
    s.run_for(1.0)
    assert len(fast) == 100
    idle["now"] = True
    s.run_for(1.0)
    assert 20 <= len(fast) - 100 <= 21
    idle["now"] = False
    before = len(fast)
    s.run_for(1.0)
    assert 96 <= len(fast) - before <= 100  # back to every tick from the next slot on


def test_without_a_predicate_or_with_stride_one_nothing_changes() -> None:
    for s in (Scheduler(VirtualClock(), 100, idle_rate_hz=20),
              Scheduler(VirtualClock(), 100, idle_rate_hz=None)):
        if s.idle_stride == 1:
            s.idle = lambda: True
        fast = recorder(s, "fast", 100)
        s.run_for(1.0)
        assert len(fast) == 100


def test_a_predicate_that_raises_means_every_tick(caplog: pytest.LogCaptureFixture) -> None:
    s = Scheduler(VirtualClock(), 100, idle_rate_hz=20)

    def broken() -> bool:
        raise RuntimeError("bug")

    s.idle = broken
    fast = recorder(s, "fast", 100)
    s.run_for(0.5)
    assert len(fast) == 50
    assert "idle predicate raised" in caplog.text


def test_input_that_starts_motion_brings_the_next_tick_to_the_next_base_slot() -> None:
    """A request arrives 0 s into a 50 ms idle wait and arms the watchdog (`hurry`): the next
    tick is the next base slot (10 ms), not the end of the stride."""
    clock = VirtualClock()
    s = Scheduler(clock, 100, idle_rate_hz=20)
    moving = {"now": False}
    s.idle = lambda: not moving["now"]
    fast = recorder(s, "fast", 100)
    a, b = socket.socketpair()
    try:
        def on_request() -> None:
            a.recv(100)
            moving["now"] = True
            s.hurry()

        s.add_reader(a.fileno(), on_request)
        s.run_for(0.2)  # idle: ticks at 0, 0.05, 0.10, 0.15
        assert [round(t, 3) for t, _ in fast] == [0.0, 0.05, 0.10, 0.15]
        b.send(b"go\n")
        s.run_once()  # the request is served in the wait and the tick comes 10 ms on
        assert fast[-1][0] == pytest.approx(0.16)
        assert fast[-1][1] == pytest.approx(0.01)
        s.run_once()
        assert fast[-1][0] == pytest.approx(0.17)
        s.hurry()  # not stretched: nothing to do
        s.run_once()
        assert fast[-1][0] == pytest.approx(0.18)
    finally:
        a.close()
        b.close()


def test_an_overrun_in_an_idle_tick_is_still_counted_against_the_base_period() -> None:
    clock = VirtualClock()
    s = Scheduler(clock, 100, idle_rate_hz=20)
    s.idle = lambda: True
    hog = {"on": False}

    def task(now: float, dt: float) -> None:
        if hog["on"]:
            clock.advance(0.025)
            hog["on"] = False

    s.add_task("hog", 100, task)
    s.run_for(0.2)
    hog["on"] = True
    s.run_for(0.2)
    assert s.stats.overruns == 1
    assert "hog" in s.stats.last_overrun_task


def test_on_the_wall_clock_a_request_wakes_a_long_idle_wait_at_once() -> None:
    """Rate 100 Hz, idle 2 Hz (stride 50 with a 1 s stall limit): a request 50 ms into the
    0.5 s wait that calls `hurry` gets its tick within a base period or so, long before the
    stride would end."""
    s = Scheduler(MonotonicClock(), 100, stall_limit=1.0, idle_rate_hz=2)
    assert s.idle_stride == 50
    moving = {"now": False}
    s.idle = lambda: not moving["now"]
    ticks: list[float] = []
    s.add_task("fast", 100, lambda now, dt: ticks.append(now))
    a, b = socket.socketpair()
    served: list[float] = []
    try:
        def on_request() -> None:
            a.recv(100)
            served.append(time.monotonic())
            moving["now"] = True
            s.hurry()

        s.add_reader(a.fileno(), on_request)
        s.run_once()  # the first tick: idle, the next one 0.5 s on
        sender = threading.Timer(0.05, lambda: b.send(b"go\n"))
        sender.start()
        s.run_once()
        sender.join()
        assert served, "the request was served in the wait"
        assert ticks[1] - served[0] < 0.2  # a base slot after it, not the stride's 0.45 s
    finally:
        a.close()
        b.close()
