"""The Executive layer of the autonomy (thesis 5.3.4, figure 5.35; SPEC 6.3): one activity
per working state of the mission machine (`ramp.statemachine`), each deciding *how* its state
gets done with the robot over MCP and the autonomy's own sensors.

    state                 activity (module)
    acquire_control       AcquireControl (control.py): acquire as `autonomy`, never from an
                          operator who holds control
    initial_localization  InitialLocalization (localize.py): sensors up, level scans, the
                          start box breaks the symmetry
    prepare_for_scan      PrepareForScan (crossing.py): to the vantage point in the start
                          region, facing the obstacle region; a fix there
    scan_for_obstacles    ScanForObstacles (scan.py): the stop-and-go 3D sweep
    detect_obstacles      DetectObstacles (scan.py): rocks and craters -> the planner's map
    plan_path_to_dig      PlanPathToDig (plan.py): a spot that does not repeat, the way there
    cross_to_dig          CrossToDig (crossing.py): follow it, stopping to localize
    excavate              Excavate (dig.py): ladder down, chain, creep, target load
    plan_path_home        PlanPathHome (plan.py): to the collector's approach, then back
    cross_home            CrossHome (crossing.py)
    dock                  Dock (collector.py): back onto both docking buttons
    deposit               Deposit (collector.py): bin up until the load falls
    decouple              Decouple (collector.py): bin down, drive clear
    relevel / rescan / relocalize   Relevel, Rescan, Relocalize (localize.py)
    stop                  (the machine's built-in StandStill)

The pieces they share: `Kit` (kit.py: the robot link, the sensors, the pose tracker, the
config, the perception calls), `RobotLink` (robot.py: commands, polls, the watchdog fed only
while moving), `PoseTracker` (pose.py: the last fix moved by odometry and the gyro),
`sensing.py` (level scans, localizations, the 3D sweep), `PlanDriver` (drive.py: the
follower with stops to localize). `Autonomy` (autonomy.py) puts them and the mission on one
scheduler; `ramp-autonomy` runs it on the robot, `ramp sim mission` in the simulator.
"""

from __future__ import annotations

from ramp.autonomy.executive.collector import Decouple, Deposit, Dock
from ramp.autonomy.executive.control import AcquireControl
from ramp.autonomy.executive.crossing import CrossHome, CrossToDig, PrepareForScan
from ramp.autonomy.executive.dig import Excavate
from ramp.autonomy.executive.kit import Kit
from ramp.autonomy.executive.localize import InitialLocalization, Relevel, Relocalize, Rescan
from ramp.autonomy.executive.plan import PlanPathHome, PlanPathToDig
from ramp.autonomy.executive.scan import DetectObstacles, ScanForObstacles
from ramp.autonomy.executive.step import Step

#: The executive as data: state -> activity class (each made fresh with the kit).
ACTIVITIES: dict[str, type[Step]] = {
    "acquire_control": AcquireControl,
    "initial_localization": InitialLocalization,
    "prepare_for_scan": PrepareForScan,
    "scan_for_obstacles": ScanForObstacles,
    "detect_obstacles": DetectObstacles,
    "plan_path_to_dig": PlanPathToDig,
    "cross_to_dig": CrossToDig,
    "excavate": Excavate,
    "plan_path_home": PlanPathHome,
    "cross_home": CrossHome,
    "dock": Dock,
    "deposit": Deposit,
    "decouple": Decouple,
    "relevel": Relevel,
    "rescan": Rescan,
    "relocalize": Relocalize,
}

__all__ = ["ACTIVITIES", "Kit", "Step"]
