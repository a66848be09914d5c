"""How long to dig this time, so the run's last deposit lands before its end (SPEC 6.3,
Productivity).

RMC scores regolith, and a cycle's travel, docking and deposit cost the same whatever the
load, so the fewest cycles that the bin can hold are the most productive. At the start of
each dig the time left, less the margin and the return, is the dig time still to spend; every
further cycle costs its overhead (`Estimates.overhead_s`: out, back, dock, deposit) of it. The
plan picks the number of cycles that digs the most, a full bin (`full_s` of digging) being the
most one cycle can carry. The last cycle digs until the bin reads full or its time is up.

When those cycles cannot all fill the bin, they share the digging evenly. The estimates are
only what was measured so far: the way home is a guess until it has been driven once (the
executive scales the way out's pace to its planned length), and it is often the longer leg.
A later cycle left only `min_dig_s` was dropped whenever its way came out slower than
guessed, which ended runs at 340 s with a quarter of their time unused (seed 1: one load of
35 kg). An even share is slack against that, and each later dig is planned again at its start
from what was measured by then. Near the end that is a shorter dig, never none while a dig of
`min_dig_s` fits. More cycles are planned only when they dig at least as much more as their
first dig gives up: a second cycle that did not fit after all (its way home 30 s slower than
estimated) had cost a third of a bin for nothing (randomized seed 306: 23 kg in one deposit,
240 s of the run unused).
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
    # One cycle digs until the bin reads full (`full_s` is only the rate's estimate: a
    # slower chain stopped at 120 s with 33 kg and 226 s of the run left) or the time is up.
    best = DigPlan(max(0.0, budget), 1)
    best_dug = best_first = max(0.0, min(budget, full_s))
    for n in range(2, MAX_CYCLES + 1):
        dig_total = budget - (n - 1) * est.overhead_s()
        share = dig_total / n
        if share < est.min_dig_s:
            break
        dug = min(dig_total, n * full_s)
        first = min(full_s, share)
        # More cycles pay only if the later ones fit, and the legs are estimates: when a
        # later cycle does not fit after all, the shorter first dig is what the run loses.
        # So more cycles are planned only when they gain at least as much as they risk.
        if dug > best_dug + 1e-9 and dug - best_dug >= best_first - first - 1e-9:
            best, best_dug, best_first = DigPlan(first, n), dug, first
    return best
