"""The executive's tunable numbers, from `autonomy.yaml`'s `mission:` block.

`ramp.autonomy.config.MISSION_FIELDS` range-checks them on load (a test keeps its defaults and
these equal); `settings_from(cfg.mission)` picks them out. Numbers no source
gives are marked ASSUMPTION with the reason for the value.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields


@dataclass(frozen=True)
class ExecutiveSettings:
    # -- sensing ------------------------------------------------------------------------------
    localize_scans: int = 10  # level scans (25 ms each) for one localization
    still_s: float = 0.3  # after a stop, before scans count as taken standing still
    vantage_x_m: float = 0.80  # 3D scan from here, facing +x: the front edge 0.1 m short of the
    #   obstacle region, as in the obstacle detector's accuracy runs (x = 0.8-0.9 m)
    # -- driving ------------------------------------------------------------------------------
    drive_speed_pct: float = 60.0  # straight stretches (the follower's default)
    relocalize_every_m: float = 1.2  # stop and localize again after this much driving
    pose_decay_m: float = 5.0  # odometry alone: confidence falls by 1/e over this distance
    obstacle_margin_m: float = 0.03  # added to every detected radius: the detector's
    #   diameter errors reach -3.7 cm and its positions 2 cm (obstacles.py)
    partial_margin_m: float = 0.10  # more for one seen only in part (in a rock's shadow)
    max_replans: int = 4  # re-plans inside one crossing (off the path after a fix)
    # -- digging and the collector ----------------------------------------------------------
    dig_target_kg: float = 36.0  # ASSUMPTION: a full bin, less a margin (the simulator's
    #   holds 40 kg); the run's time left shortens the dig (statemachine.productivity)
    dig_rate_kg_s: float = 0.3  # ASSUMPTION: the simulator's rate at full chain speed, until
    #   a dig has measured it
    dig_max_s: float = 150.0  # give up digging a spot after this long (a full bin: ~120 s)
    chain_speed_pct: float = 100.0
    creep_speed_pct: float = 3.0  # forward while digging (about 9 mm/s)
    dock_speed_pct: float = 12.0  # the last centimetres backwards onto the buttons
    dump_done_kg: float = 0.5  # the bin counts as empty below this


def settings_from(mission: Mapping[str, float]) -> ExecutiveSettings:
    """The executive's numbers out of `AutonomyConfig.mission` (other names are left alone)."""
    values: dict[str, float | int] = {}
    for f in fields(ExecutiveSettings):
        if f.name in mission:
            v = mission[f.name]
            values[f.name] = int(v) if f.type in ("int", int) else float(v)
    return ExecutiveSettings(**values)  # type: ignore[arg-type]
