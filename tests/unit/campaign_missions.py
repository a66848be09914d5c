"""Small, real mission functions for the campaign runner's tests (the real mission is another
module's job). Each computes its summary from its arguments alone, deterministically."""

from __future__ import annotations

import math
import random
from typing import Any

from ramp.autonomy.planning import Planner, plan_to_dock
from tests.unit.rmc_layouts import random_layout, random_start

SPEED_M_S = 0.18  # MARTE at 60 %


def planned_trip(seed: int, start_box: str, heading: int, fault: str,
                 duration: float) -> dict[str, Any]:
    """A layout and start pose from the seed, a plan to the digging region and back to the
    collector; the 'mission' digs and delivers for whatever time the driving leaves."""
    rng = random.Random(f"{seed}|{start_box}|{heading}")
    arena = random_layout(rng)
    start = random_start(rng, start_box, heading)
    planner = Planner(arena)
    out = planner.plan(start, (5.2, 1.94), 0.0)
    if not out.ok:
        return summary(seed, start_box, heading, fault, "error", 0.0, 0.0)
    back, _dock = plan_to_dock(planner, planner_end(out))
    driving = (out.length_m + back.length_m) / SPEED_M_S
    sim_time = min(duration, driving + 60.0)
    delivered = round(max(0.0, duration - driving) / 60.0 * (0.5 if fault != "none" else 1.0)
                      + (seed % 4), 3)
    return summary(seed, start_box, heading, fault, "completed", delivered, sim_time,
                   collisions=1 if seed % 5 == 4 else 0)


def planner_end(result: Any) -> Any:
    from ramp.autonomy.planning import Pose

    leg = result.legs[-1]
    return Pose(leg.points[-1, 0], leg.points[-1, 1], leg.final_yaw or 0.0)


def summary(seed: int, start_box: str, heading: int, fault: str, outcome: str,
            delivered: float, sim_time: float, collisions: int = 0) -> dict[str, Any]:
    return {"outcome": outcome, "delivered_kg": delivered, "sim_time_s": round(sim_time, 1),
            "wall_time_s": 0.0, "collisions": collisions, "crater_entries": 0,
            "states_visited": 3, "localization_losses": seed % 3, "seed": seed,
            "start_box": start_box, "heading": heading, "fault": fault}


def arithmetic(seed: int, start_box: str, heading: int, fault: str,
               duration: float) -> dict[str, Any]:
    """Cheap: kilograms from a seeded generator keyed by every argument."""
    rng = random.Random(f"{seed}|{start_box}|{heading}|{fault}|{duration}")
    delivered = round(rng.uniform(5.0, 20.0), 3)
    return summary(seed, start_box, heading, fault, "completed", delivered,
                   round(duration * rng.uniform(0.5, 1.0), 1),
                   collisions=int(rng.random() < 0.2))


def breaks_on_seed_13(seed: int, start_box: str, heading: int, fault: str,
                      duration: float) -> dict[str, Any]:
    if seed == 13:
        raise RuntimeError(f"simulated crash on seed {seed}")
    if seed == 14:
        return {"outcome": "completed"}  # no delivered_kg, no counters: not a summary
    return arithmetic(seed, start_box, heading, fault, math.floor(duration))


def says_randomized(seed: int, start_box: str, heading: int, fault: str, duration: float,
                    randomize: bool = False) -> dict[str, Any]:
    """Delivers 20 kg when told to randomize, 0 otherwise."""
    return summary(seed, start_box, heading, fault, "completed", 20.0 if randomize else 0.0,
                   duration)


def chatty(seed: int, start_box: str, heading: int, fault: str,
           duration: float) -> dict[str, Any]:
    """As `arithmetic`, warning on the way as a real run's interlocks and re-plans do."""
    import logging

    logging.getLogger("ramp.interlocks").warning("interlock digging_creep active: test")
    return arithmetic(seed, start_box, heading, fault, duration)
