"""How long to dig this time, so the run's last deposit lands before its end (SPEC 6.3,
Productivity).

RMC scores regolith, and a cycle's travel, docking and deposit cost the same whatever the
load, so the fewest cycles that the bin can hold are the most productive. At the start of
each dig the time left, less the margin and the return, is the dig time still to spend; every
further cycle costs its overhead (`Estimates.overhead_s`: out, back, dock, deposit) of it. The
plan picks the number of cycles that digs the most, a full bin (`full_s` of digging) being the
most one cycle can carry.

When those cycles cannot all fill the bin, they share the digging evenly. The estimates are
only what was measured so far: the way home is a guess until it has been driven once, and it
is often the longer leg. A later cycle left only `min_dig_s` was dropped whenever its way came
out slower than guessed, which ended runs at 340 s with a quarter of their time unused (seed
1: one load of 35 kg). An even share is slack against that, and each later dig is planned
again at its start from what was measured by then. Near the end that is a shorter dig, never
none while a dig of `min_dig_s` fits.
"""

from __future__ import annotations

from dataclasses import dataclass

from ramp.statemachine.context import Estimates

MAX_CYCLES = 20  # far more than a run holds; bounds the search


@dataclass(frozen=True)
class DigPlan:
    """This dig's length and how many cycles (this one included) the plan expects."""

    dig_s: float
    cycles: int


def plan_dig(left_s: float, margin_s: float, est: Estimates, full_s: float) -> DigPlan:
    """The dig that makes the run deliver the most: `left_s` seconds remain when the dig
    begins, the last deposit is done `margin_s` before the end, and a full bin takes `full_s`
    of digging."""
    budget = left_s - margin_s - est.return_s()
    best = DigPlan(max(0.0, min(budget, full_s)), 1)
    best_dug = best.dig_s
    for n in range(2, MAX_CYCLES + 1):
        dig_total = budget - (n - 1) * est.overhead_s()
        share = dig_total / n
        if share < est.min_dig_s:
            break
        dug = min(dig_total, n * full_s)
        if dug > best_dug + 1e-9:
            best, best_dug = DigPlan(min(full_s, share), n), dug
    return best
