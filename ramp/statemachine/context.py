"""What the mission's states share: one `MissionContext`, handed to every activity's `start`.

The machine reads a few fields to decide (the pose confidence before any driving state, the
bin load and the time budget near the end of the run) and writes the bookkeeping it owns
(`localization_losses`, `faults`, the measured `estimates`). Everything else belongs to the
activities: they write what they learn (pose, obstacles, plan, load) for the next one to use.

Times are seconds on the mission's clock (the `now` the scheduler hands to `tick`), never
wall time. Poses are SPEC 6.1's arena frame: x along the arena from the collector wall, y
across with +y on the left, yaw counter-clockwise from +x in radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # for the field types only: the machine runs without the autonomy loaded
    #   (the executive imports the machine; the machine must not import it back)
    from ramp.autonomy.planning import (
        DigSites,
        DigSpot,
        Disc,
        DockApproach,
        Planner,
        PlanResult,
        Pose,
    )


@dataclass
class TimeBudget:
    """The run's time: it started at `start_s` and lasts `duration_s`; no new dig/dump
    cycle starts, and the last return leaves, `margin_s` before its end."""

    start_s: float = 0.0
    duration_s: float = 600.0
    margin_s: float = 30.0

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def elapsed(self, now: float) -> float:
        return now - self.start_s

    def left(self, now: float) -> float:
        """Seconds until the run is over (negative once it is)."""
        return self.end_s - now


@dataclass
class Estimates:
    """How long the mission's legs take, to decide near the end of the run.

    They start at the configured guesses and the machine replaces them with what it measured
    (a rise at once, a fall halfway), so a slow arena or a recovery makes the end decision
    more careful. An activity that knows better (a planner that measured the way home) may
    write them too.
    """

    trip_s: float = 60.0  # out, from the collector to a digging spot, planning included
    dock_deposit_s: float = 60.0  # dock, deposit and decouple at the collector
    min_dig_s: float = 30.0  # the shortest dig worth a trip
    #: Back, from a digging spot to the collector's approach. Measured apart from the way
    #: out: the way home ends with the docking approach and is often the longer one, and
    #: twice the longer of the two made a second cycle look 60 s longer than it was.
    home_s: float = 60.0
    #: False until the way home has been driven once: until then `home_s` is a guess that an
    #: activity may refine (the way out's pace over the way home's planned length).
    home_measured: bool = False

    def return_s(self) -> float:
        """From the digging region to regolith out of the bin."""
        return self.home_s + self.dock_deposit_s

    def overhead_s(self) -> float:
        """What a cycle costs besides its dig: out, back, dock, deposit and decouple."""
        return self.trip_s + self.home_s + self.dock_deposit_s

    def cycle_s(self) -> float:
        """From the collector out to dig (at least `min_dig_s`) and back, deposited."""
        return self.overhead_s() + self.min_dig_s

    @staticmethod
    def blend(old: float, measured: float) -> float:
        """Rise to a longer measurement at once, come down halfway to a shorter one."""
        return max(measured, 0.5 * (old + measured))


@dataclass
class MissionContext:
    """The mission's shared state. Activities read and write it; the machine reads the pose
    confidence, the bin load and the time budget, and keeps the counters."""

    budget: TimeBudget = field(default_factory=TimeBudget)
    estimates: Estimates = field(default_factory=Estimates)

    # -- where the robot is (the localizer writes these, between scans too) ---------------
    pose: Pose | None = None  # estimated pose in the arena frame
    pose_confidence: float = 0.0  # 0 (no idea) .. 1 (certain); must decay without fixes
    pose_time_s: float = math.nan  # when the pose was last fixed from a scan
    heading_hint: float | None = None  # the start heading known before the run (rad)

    # -- what it found (scan_for_obstacles / detect_obstacles) ----------------------------
    obstacle_scan: Any = None  # the 3D scan as perception records it (ScanRecords)
    localization_scan: Any = None  # the newest scan taken to localize (rescan -> relocalize)
    rocks: list[Disc] = field(default_factory=list)  # detected, arena frame
    craters: list[Disc] = field(default_factory=list)
    planner: Planner | None = None  # built from what was detected
    dig_sites: DigSites | None = None  # spots that never repeat

    # -- where it is going ------------------------------------------------------------------
    dig_spot: DigSpot | None = None  # the spot being driven to or dug; None once dug
    dig_spots_done: list[DigSpot] = field(default_factory=list)
    plan: PlanResult | None = None  # the plan being driven (legs), None when there is none
    dock: DockApproach | None = None  # the collector approach of the plan home

    # -- regolith ---------------------------------------------------------------------------
    bin_kg: float = 0.0  # the load in the bin now (`ble:load.kg`)
    delivered_kg: float = 0.0  # estimated delivered: the bin's drops while docked
    deposits: int = 0

    # -- bookkeeping the machine keeps ---------------------------------------------------------
    localization_losses: int = 0  # losses that interrupted a task (SPEC 6.3 summary)
    faults: int = 0  # faults and failures that interrupted a task
    last_problem: str = ""  # the newest lost / fault / failed reason
    control_owner: str = ""  # the newest `robot:control.owner` the machine was told of

    #: Anything else two activities need to pass between them, by a name they agree on.
    notes: dict[str, Any] = field(default_factory=dict)

    def pose_is_confident(self, threshold: float) -> bool:
        """True when there is a pose and the localizer trusts it at least `threshold`."""
        return self.pose is not None and self.pose_confidence >= threshold
