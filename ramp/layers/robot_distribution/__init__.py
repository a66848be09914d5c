"""Robot Distribution layer: the robot-wide rules of every request (module state, control
ownership, the watchdog) and the robot's own requests (`robot:robot.get=()` ...)."""

from __future__ import annotations

from ramp.layers.robot_distribution.robot import (
    Client,
    Health,
    ModuleSlot,
    RobotDistribution,
    RobotRequests,
)

__all__ = ["Client", "Health", "ModuleSlot", "RobotDistribution", "RobotRequests"]
