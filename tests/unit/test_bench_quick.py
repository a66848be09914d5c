"""`python -m bench --quick` means under two minutes on 2 cores (issue 35: it ran past 5).

Measured, it is the sections' fixed waits on the clock plus their work; this checks the
waits the quick profile asks for, which were 205 s before (45 s of console bandwidth, two
40 s realtime missions, three trials of everything; the run took 284 s) and leave room for
the work now."""

from __future__ import annotations

from bench import console_bandwidth, realtime, recorder
from bench.common import PROFILES


def quick_waits() -> float:
    s = PROFILES["quick"]
    tick_s, _, sup_s = recorder.PROFILE["quick"]
    return (3 * s.tick_duration_s                                  # tick: three runs
            + s.rt_trials * 2 * s.tick_duration_s                  # interlocks: 2 configs
            + s.rt_trials * len(s.tp_clients) * 2 * s.tp_duration_s  # round_trip throughput
            + 2 * 2 * s.c2w_flood_s                                # command_to_wire floods
            + s.rss_after_s + tick_s + sup_s
            + console_bandwidth.SECONDS["quick"]
            + len(realtime.MODES) * realtime.SECONDS["quick"])         # three missions


def test_the_quick_profile_waits_under_a_minute_on_the_clock() -> None:
    assert quick_waits() <= 60.0, quick_waits()
    assert PROFILES["quick"].rt_trials == 1  # the full run keeps three and their median
    assert PROFILES["full"].rt_trials == 3
