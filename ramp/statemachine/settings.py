"""The mission's tunable numbers, from `autonomy.yaml`'s `mission:` block.

`ramp.autonomy.config` checks the block on load (known names range-checked, any other named
number accepted); `MissionConfig.from_mapping(cfg.mission)` picks what the state machine uses.
Each state's timeout can be set as `timeout_<state>_s` (for example `timeout_excavate_s:
240`); the defaults are in `ramp.statemachine.table.STATES`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType

from ramp.errors import ConfigError
from ramp.statemachine.table import STATE, STATES


def default_timeouts() -> Mapping[str, float]:
    return MappingProxyType({s.name: s.timeout_s for s in STATES if s.timeout_s is not None})


@dataclass(frozen=True)
class MissionConfig:
    # ASSUMPTION where no source says: the trip, dock/deposit and dig times are first guesses
    # for MARTE on the RMC arena; the machine replaces them with what it measures.
    duration_s: float = 600.0  # the RMC run (SPEC 6.3 `--duration`)
    end_margin_s: float = 30.0  # no new cycle starts, and the last return leaves, this early
    max_relocalize_tries: int = 3  # then wait for the operator (SPEC 6.3)
    max_step_retries: int = 3  # a step that faults or fails is tried again this many times
    min_pose_confidence: float = 0.5  # below it the robot is lost and must not drive
    min_return_load_kg: float = 1.0  # the last return pays only with at least this much
    trip_estimate_s: float = 60.0  # collector <-> digging spot, until measured
    dock_deposit_estimate_s: float = 60.0  # dock + deposit + decouple, until measured
    min_dig_s: float = 30.0  # no cycle starts without time to dig at least this long
    stop_settle_s: float = 1.0  # the built-in `stop` activity waits this long
    timeouts_s: Mapping[str, float] = field(default_factory=default_timeouts)

    @classmethod
    def from_mapping(cls, mission: Mapping[str, float]) -> MissionConfig:
        """From `AutonomyConfig.mission`. Unknown names are left for the activities;
        `timeout_<state>_s` must name a state that has a timeout."""
        known = {f.name: f.type for f in fields(cls) if f.name != "timeouts_s"}
        values: dict[str, float | int] = {}
        for name in known:
            if name in mission:
                v = mission[name]
                values[name] = int(v) if name.startswith("max_") else float(v)
        timeouts = dict(default_timeouts())
        for key, v in mission.items():
            if not (key.startswith("timeout_") and key.endswith("_s")):
                continue
            state = key[len("timeout_"):-len("_s")]
            if state not in timeouts:
                have = ", ".join(sorted(timeouts))
                raise ConfigError(f"no state named {state!r} has a timeout (states: {have})",
                                  key=f"mission.{key}")
            if not v > 0:
                raise ConfigError(f"{v!r} is not a time in s (> 0)", key=f"mission.{key}")
            timeouts[state] = float(v)
        return cls(**values, timeouts_s=MappingProxyType(timeouts))  # type: ignore[arg-type]

    def timeout_of(self, state: str) -> float | None:
        if state not in STATE:
            raise KeyError(state)
        return self.timeouts_s.get(state)
