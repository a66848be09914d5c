"""Planning for the RMC mission (thesis 5.3.4, SPEC 6.3): where to go and how to drive there.

Pure numpy and Python, deterministic, no I/O, so the state machine can call it from its tick
and tests can call it with made-up arenas:

- `OccupancyGrid` / `PlannerConfig` — the arena in 5 cm cells, walls and obstacles inflated by
  the robot's half-width plus a margin, with costs that keep turning room.
- `Planner.plan(start, goal, goal_yaw)` — A* (8-connected, octile), shortcut, checked against
  the exact rectangular footprint as it will be driven; legs to drive or a reason.
- `DigSites` — digging spots that never repeat, nearest trip first.
- `plan_to_dock` / `docking_approaches` — the approach in front of the collector and the
  straight reverse onto the x = 0 wall.
- `PathFollower` — pure pursuit with turns in place, giving `base:base.drive` speed and
  direction.
"""

from ramp.autonomy.planning.astar import SearchResult, astar, bfs_steps, dijkstra
from ramp.autonomy.planning.dig_spots import DigConfig, DigSites, DigSpot, Trench
from ramp.autonomy.planning.docking import DockApproach, docking_approaches, plan_to_dock
from ramp.autonomy.planning.follower import DriveCommand, FollowerConfig, PathFollower
from ramp.autonomy.planning.geometry import ArenaMap, Disc, Pose, footprint_clearance
from ramp.autonomy.planning.grid import OccupancyGrid, PlannerConfig
from ramp.autonomy.planning.path import Path, densify, swept_poses
from ramp.autonomy.planning.planner import Planner, PlanResult

__all__ = [
    "ArenaMap", "DigConfig", "DigSites", "DigSpot", "Disc", "DockApproach", "DriveCommand",
    "FollowerConfig", "OccupancyGrid", "Path", "PathFollower", "PlanResult", "Planner",
    "PlannerConfig", "Pose", "SearchResult", "Trench", "astar", "bfs_steps", "densify",
    "dijkstra", "docking_approaches", "footprint_clearance", "plan_to_dock", "swept_poses",
]
