"""Scheduler on a virtual clock: rates, dt, skipping without bursts, overrun naming, I/O."""

from __future__ import annotations

import os
import socket

import pytest

from ramp.clock import VirtualClock
from ramp.scheduler import Scheduler


def test_tasks_run_at_their_divisor_rates_with_dt() -> None:
    clock = VirtualClock()
    s = Scheduler(clock, 100)
    seen: dict[str, list[tuple[float, float]]] = {"fast": [], "slow": [], "ten": []}
    s.add_task("fast", 100, lambda now, dt: seen["fast"].append((now, dt)))
    s.add_task("slow", 20, lambda now, dt: seen["slow"].append((now, dt)))
    s.add_task("ten", 10, lambda now, dt: seen["ten"].append((now, dt)))
    s.run_for(1.0)
    assert len(seen["fast"]) == 100
    assert len(seen["slow"]) == 20
    assert len(seen["ten"]) == 10
    assert all(dt == pytest.approx(0.05) for _, dt in seen["slow"])
    assert seen["slow"][1][0] - seen["slow"][0][0] == pytest.approx(0.05)


def test_rate_that_does_not_divide_is_refused() -> None:
    s = Scheduler(VirtualClock(), 100)
    with pytest.raises(ValueError, match="does not divide"):
        s.add_task("odd", 30, lambda now, dt: None)
    with pytest.raises(ValueError):
        Scheduler(VirtualClock(), 0)


@pytest.mark.parametrize(("base", "asked", "rate"), [
    (100, 50, 50), (100, 100, 100), (100, 30, 25), (100, 1000, 100), (60, 50, 30),
    (200, 50, 50), (100, 0.1, 0.1),
])
def test_rate_at_most_is_the_fastest_divisor_rate_no_faster_than_asked(
        base: float, asked: float, rate: float) -> None:
    s = Scheduler(VirtualClock(), base)
    assert s.rate_at_most(asked) == pytest.approx(rate)
    s.add_task("t", s.rate_at_most(asked), lambda now, dt: None)  # always accepted


@pytest.mark.parametrize("asked", [0, -5, float("nan"), float("inf")])
def test_rate_at_most_refuses_what_is_no_rate(asked: float) -> None:
    with pytest.raises(ValueError, match="positive number of Hz"):
        Scheduler(VirtualClock(), 100).rate_at_most(asked)


def test_overrun_skips_missed_ticks_and_names_the_task() -> None:
    clock = VirtualClock()
    s = Scheduler(clock, 100)
    runs: list[float] = []
    state = {"slow": False}

    def hog(now: float, dt: float) -> None:
        if state["slow"]:
            state["slow"] = False
            clock.advance(0.047)  # this task "takes" 47 ms

    s.add_task("quick", 100, lambda now, dt: runs.append(now))
    s.add_task("hog", 100, hog)
    s.run_for(0.1)
    before = len(runs)
    state["slow"] = True
    s.run_for(0.2)
    # 0.2 s at 100 Hz is 20 ticks: the 47 ms task swallowed the deadlines 0.11-0.14, which
    # are skipped; the loop resumes at 0.15 on the grid, and nothing is replayed in a burst.
    assert len(runs) - before == 16
    gaps = [b - a for a, b in zip(runs, runs[1:], strict=False)]
    assert min(gaps) >= 0.01 - 1e-9
    assert s.stats.overruns == 1
    assert s.stats.skipped == 4
    assert s.stats.last_overrun_task.startswith("hog (47.0 ms)")


def test_a_raising_task_does_not_stop_the_loop() -> None:
    s = Scheduler(VirtualClock(), 100)
    count = {"n": 0}

    def bad(now: float, dt: float) -> None:
        raise RuntimeError("boom")

    s.add_task("bad", 100, bad)
    s.add_task("good", 100, lambda now, dt: count.__setitem__("n", count["n"] + 1))
    s.run_for(0.1)
    assert count["n"] == 10
    assert s.tasks[0].errors == 10


def test_lateness_statistics() -> None:
    clock = VirtualClock()
    s = Scheduler(clock, 100)
    s.add_task("t", 100, lambda now, dt: None)
    s.run_for(1.0)
    p50, p99, mx = s.stats.percentiles()
    assert (p50, p99, mx) == (0.0, 0.0, 0.0)
    assert s.stats.ticks == 100


def test_input_is_dispatched_during_the_wait() -> None:
    s = Scheduler(VirtualClock(), 100)
    a, b = socket.socketpair()
    got: list[bytes] = []
    s.add_reader(a.fileno(), lambda: got.append(a.recv(100)))
    b.send(b"hello")
    s.run_once()
    assert got == [b"hello"]
    s.remove_reader(a.fileno())
    a.close()
    b.close()


def test_a_closed_fd_left_registered_is_dropped() -> None:
    s = Scheduler(VirtualClock(), 100)
    r, w = os.pipe()
    s.add_reader(r, lambda: None)
    os.close(r)
    os.close(w)
    s.run_for(0.05)  # must not raise or spin
    assert r not in s._readers


def test_io_dispatch_stops_at_the_deadline_and_rotates() -> None:
    clock = VirtualClock()
    s = Scheduler(clock, 100)
    pairs = [socket.socketpair() for _ in range(3)]
    served: list[int] = []

    def serve(i: int) -> None:
        served.append(i)
        clock.advance(0.004)  # each client's turn costs 4 ms

    for i, (a, b) in enumerate(pairs):
        s.add_reader(a.fileno(), lambda i=i: serve(i))
        b.send(b"x")  # never read: stays readable
    assert s.poll_io(0.0, deadline=clock.now() + 0.005) == 2  # the third waits for the tick
    first = served[:]
    served.clear()
    assert s.poll_io(0.0, deadline=clock.now() + 0.005) == 2
    assert served != first  # the next pass starts with someone else
    assert s.poll_io(0.0) == 3  # no deadline: everyone
    for a, b in pairs:
        a.close()
        b.close()


def test_slower_tasks_keep_running_when_overruns_skip_ticks_unevenly() -> None:
    """Skips of 1 and 2 ticks used to leave the index odd forever, starving every task with
    an even divisor (the lift controller, the hot-plug retry)."""
    clock = VirtualClock()
    s = Scheduler(clock, 100)
    runs = {"50": 0, "1": 0}
    state = {"n": 0}

    def heavy(now: float, dt: float) -> None:
        state["n"] += 1
        clock.advance(0.025 if state["n"] == 7 else 0.015)  # 1.5 periods, once 2.5

    s.add_task("heavy", 100, heavy)
    s.add_task("fifty", 50, lambda now, dt: runs.__setitem__("50", runs["50"] + 1))
    s.add_task("one", 1, lambda now, dt: runs.__setitem__("1", runs["1"] + 1))
    s.run_for(10.0)
    # every tick overruns, so about 1 in 2 base ticks runs; the 50 Hz task still runs at
    # every run tick at or past its slot, and the 1 Hz task once a second
    assert runs["50"] > 400
    assert 9 <= runs["1"] <= 11


def test_below_descriptor_1024_the_wait_is_one_microsecond_select(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """One wake-up per wait, as the bare loop (poll, which rounds to milliseconds, is only
    used once a descriptor is past select's reach); a descriptor closed under the loop is
    still found and dropped."""
    import select
    import time

    import ramp.scheduler

    s = Scheduler(VirtualClock(), 100)
    a, b = socket.socketpair()
    s.add_reader(a.fileno(), lambda: None)
    asked: list[float] = []
    real = select.select

    def recording(r: object, w: object, x: object, timeout: float) -> object:
        asked.append(timeout)
        return real(r, w, x, timeout)  # type: ignore[arg-type]

    monkeypatch.setattr(ramp.scheduler.select, "select", recording)
    t0 = time.perf_counter()
    s.poll_io(0.0047)
    assert time.perf_counter() - t0 >= 0.0045
    assert asked == [0.0047]  # one select, the whole wait, to the microsecond
    b.send(b"x")
    assert s._ready_select(0.0006) == ([a.fileno()], [])
    fd = a.fileno()
    a.close()
    s._ready_select(0.0)
    assert fd not in s._readers and "dropping closed file descriptor" in caplog.text
    b.close()
