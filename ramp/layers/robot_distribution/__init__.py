"""Robot Distribution layer: the robot-wide view of every request (which module, is it
attached, who owns control), the watchdog, the module registry and the robot's own requests
(`robot:robot.get=()` ...)."""

from __future__ import annotations

from ramp.layers.robot_distribution.context import Client, RequestContext
from ramp.layers.robot_distribution.control import Control
from ramp.layers.robot_distribution.interlocks import Interlocks, RuleSpec
from ramp.layers.robot_distribution.registry import ModuleRegistry, ModuleSlot
from ramp.layers.robot_distribution.robot import Health, RobotDistribution, RobotRequests
from ramp.layers.robot_distribution.watchdog import Watchdog

__all__ = ["Client", "Control", "Health", "Interlocks", "ModuleRegistry", "ModuleSlot",
           "RequestContext", "RobotDistribution", "RobotRequests", "RuleSpec", "Watchdog"]
