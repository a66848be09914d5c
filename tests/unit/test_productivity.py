"""The dig length that makes a run deliver the most (SPEC 6.3 Productivity)."""

from __future__ import annotations

import pytest

from ramp.statemachine import Estimates
from ramp.statemachine.productivity import plan_dig

# A cycle's overhead of 2 x 50 + 30 = 130 s; the return 80 s; a full bin 120 s of digging.
EST = Estimates(trip_s=50.0, dock_deposit_s=30.0, min_dig_s=30.0, home_s=50.0)
FULL_S = 120.0


def test_with_time_for_one_full_bin_and_a_second_it_digs_the_bin_full_first() -> None:
    # 500 s left: 500 - 30 - 80 = 390 s; two cycles dig 390 - 130 = 260 s -> 2 x 120 (full).
    plan = plan_dig(500.0, 30.0, EST, FULL_S)
    assert plan.cycles == 2
    assert plan.dig_s == pytest.approx(FULL_S)


def test_two_cycles_that_cannot_both_fill_the_bin_share_the_digging_evenly() -> None:
    # 400 s left: 290 s to dig; two cycles dig 160 s (one cycle: only 120 s), 80 s each:
    # the second has 50 s of slack over the shortest dig against a slow way home.
    plan = plan_dig(400.0, 30.0, EST, FULL_S)
    assert plan.cycles == 2
    assert plan.dig_s == pytest.approx(80.0)


def test_more_cycles_are_planned_only_when_they_gain_what_they_risk() -> None:
    # 370 s left: two cycles would dig 130 s (65 s each) against one full bin (120 s): 10 s
    # more if the second cycle fits, 55 s less if it does not. One cycle, digging until full.
    plan = plan_dig(370.0, 30.0, EST, FULL_S)
    assert plan.cycles == 1
    # Randomized seed 306 at its first dig: two shares of 76 s against one full bin of 120 s
    # (32 s more, 44 s at risk). The way home then took 136 s, not 105, and the second cycle
    # did not fit: one load of 23 kg where one full bin was 36 kg.
    est = Estimates(trip_s=57.2, dock_deposit_s=35.0, min_dig_s=30.0, home_s=104.9)
    plan = plan_dig(519.7, 30.0, est, 120.06)
    assert plan.cycles == 1


def test_an_even_share_keeps_the_second_cycle_when_the_way_home_is_slower_than_guessed(
        ) -> None:
    """Seed 1 as it ran: the first dig began with 503 s left, the way out measured (72 s),
    the way home and the dock guessed (60 s each). Home took 93 s and docking 32 s. Filling
    the bin first (120 s) left 228 s after the first deposit against a 241 s cycle: the run
    ended at 342 s with one load. The even share digs 80.5 s and leaves the second cycle
    room."""
    guessed = Estimates(trip_s=72.0, dock_deposit_s=60.0, min_dig_s=30.0, home_s=60.0)
    plan = plan_dig(503.0, 30.0, guessed, FULL_S)
    assert plan.cycles == 2
    assert plan.dig_s == pytest.approx((503.0 - 30.0 - 120.0 - 192.0) / 2)
    measured = Estimates(trip_s=72.0, dock_deposit_s=46.0, min_dig_s=30.0, home_s=93.0)
    first_cycle = plan.dig_s + 93.0 + 32.0  # the dig, home, dock and deposit as they ran
    left_after = 503.0 - first_cycle
    assert left_after - 30.0 >= measured.cycle_s()


def test_near_the_end_the_last_dig_is_shorter_so_the_deposit_lands_before_the_end() -> None:
    # 170 s left: the return (80 s) and the margin (30 s) leave 60 s of digging, not 120.
    plan = plan_dig(170.0, 30.0, EST, FULL_S)
    assert plan.cycles == 1
    assert plan.dig_s == pytest.approx(60.0)


def test_with_no_time_to_dig_it_plans_no_dig() -> None:
    assert plan_dig(100.0, 30.0, EST, FULL_S).dig_s == 0.0


def test_a_second_cycle_whose_dig_would_be_shorter_than_the_shortest_is_not_planned() -> None:
    # 290 s left: 180 s to dig; two cycles would dig 25 s each (< 30 s): one cycle, which
    # may dig all 180 s (the bin reading full ends it sooner).
    plan = plan_dig(290.0, 30.0, EST, FULL_S)
    assert plan.cycles == 1
    assert plan.dig_s == pytest.approx(180.0)


def test_the_only_cycle_left_digs_past_the_rate_estimate_until_the_bin_is_full() -> None:
    """Randomized seed 309: the chain brought 0.277 kg/s against the 0.3 planned, and a dig
    stopped at the estimate's 120 s with 33 kg in the bin and 226 s of the run unused."""
    plan = plan_dig(486.0, 30.0, Estimates(trip_s=79.0, dock_deposit_s=35.0, min_dig_s=30.0,
                                           home_s=109.0), FULL_S)
    assert plan.cycles == 1
    assert plan.dig_s == pytest.approx(486.0 - 30.0 - 109.0 - 35.0)


def test_a_cycle_counts_the_way_out_and_the_way_home_each_once() -> None:
    # Randomized seed 1: out 64 s, home 119 s, dock and deposit 35 s. Twice the longer leg
    # made a cycle 303 s and ended the run at 320 s with 279 s left; it takes 248 s.
    est = Estimates(trip_s=64.0, dock_deposit_s=35.0, min_dig_s=30.0, home_s=119.0)
    assert est.cycle_s() == pytest.approx(64.0 + 119.0 + 30.0 + 35.0)
    assert est.return_s() == pytest.approx(119.0 + 35.0)
