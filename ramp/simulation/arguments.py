"""Bounds on the `ramp sim` commands' numbers, checked before anything runs.

A seed, a count or a time outside what a run can use is a usage error naming the option and
what was expected (exit 2), not a traceback or a run that allocates until it fails: a seed
is what numpy's generators take, a campaign's runs fit in memory and finish this year, a run's
length is at most a day of simulated time (a cluster address is
`ramp.simulation.campaign.check_cluster_address`'s, on the shared host:port parser).
"""

from __future__ import annotations

import math

MAX_SEED = 2**32 - 1  # numpy's SeedSequence takes any non-negative int; this bounds the text
MAX_RUNS = 100_000  # a campaign's table and report are held in memory
MAX_DURATION_S = 86_400.0  # a day of simulated time
MAX_WORKERS = 1024
MAX_YAW_DEG = 360.0


class ArgumentError(ValueError):
    """A number out of its bounds; the message names the option and what was expected."""


def check_seed(seed: int, runs: int = 1, option: str = "--seed") -> None:
    """`seed` .. `seed + runs - 1` must all be seeds."""
    if not 0 <= seed <= MAX_SEED - (runs - 1):
        top = MAX_SEED - (runs - 1)
        raise ArgumentError(f"{option}: expected a whole number 0-{top}"
                            + (f" (with --runs {runs})" if runs > 1 else "") + f", got {seed}")


def check_runs(runs: int) -> None:
    if not 1 <= runs <= MAX_RUNS:
        raise ArgumentError(f"--runs: expected 1-{MAX_RUNS}, got {runs}")


def check_workers(workers: int | None) -> None:
    if workers is not None and not 1 <= workers <= MAX_WORKERS:
        raise ArgumentError(f"--workers: expected 1-{MAX_WORKERS}, got {workers}")


def check_duration(duration: float) -> None:
    if not (math.isfinite(duration) and 0.0 < duration <= MAX_DURATION_S):
        raise ArgumentError(f"--duration: expected a positive number of seconds up to "
                            f"{MAX_DURATION_S:g}, got {duration:g}")


def check_yaw(yaw_deg: float, option: str) -> None:
    if not (math.isfinite(yaw_deg) and -MAX_YAW_DEG <= yaw_deg <= MAX_YAW_DEG):
        raise ArgumentError(f"{option}: expected a yaw in degrees, -{MAX_YAW_DEG:g} to "
                            f"{MAX_YAW_DEG:g}, got {yaw_deg:g}")
