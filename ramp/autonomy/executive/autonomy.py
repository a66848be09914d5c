"""The whole autonomy on one scheduler: the MCP link, the executive, the mission machine.

The same assembly runs on the robot (`ramp-autonomy`: Phidget and Hokuyo drivers, the wall
clock) and in the simulator (`ramp sim mission`: the rig's drivers on the emulators, a
virtual clock). The caller brings the scheduler and the sensing (`Perception`, its tasks
already added, so they run first in every tick); this adds, in data order:

    autonomy.mcp    the link's own work (connect, time out; replies are read by the loop
                    the moment they arrive)                               50 Hz
    autonomy.poll   `RobotLink`: polls robot/base/ble, watchdog feeding  20 Hz
    autonomy.pose   the pose tracker (after odometry and the AHRS), the bin load into the
                    mission's context                                     mission rate
    mission         `Mission.tick`: the machine and the current activity  mission rate

The link has no heartbeat of its own: the executive feeds the backend's watchdog only while
it means to move (`RobotLink`). Every `robot.get` answer's owner goes to
`Mission.observe_control` (an operator's takeover pauses the mission; control free again
resumes it), a watchdog trip while moving to `Mission.report_fault`, and another owner makes
the pose tracker forget its prior (the operator may move the robot anywhere).
"""

from __future__ import annotations

import math
import ssl
from collections.abc import Callable

from ramp.autonomy.config import AutonomyConfig
from ramp.autonomy.executive import ACTIVITIES
from ramp.autonomy.executive.kit import Detect, Kit, Localize
from ramp.autonomy.executive.robot import RobotLink
from ramp.autonomy.mcp_link import McpLink
from ramp.autonomy.perception.stack import Perception
from ramp.scheduler import ScheduledTask, Scheduler
from ramp.statemachine import Activity, Executive, Mission, MissionConfig

OWNER = "autonomy"  # SPEC 6.3: the autonomy acquires control under this name
MISSION_HZ = 20.0
POLL_TASK_HZ = 20.0
#: The link's own task: time-outs and what the socket would not take at once. Replies are read
#: the moment they arrive (the loop watches the socket), so this is not their latency.
LINK_HZ = 50.0


class Autonomy:
    """The link, the executive and the mission, as tasks on `scheduler`."""

    def __init__(self, scheduler: Scheduler, perception: Perception, config: AutonomyConfig,
                 backend: str | tuple[str, int], *, localize: Localize | None = None,
                 detect: Detect | None = None, start_box: str | None = None,
                 mission_hz: float = MISSION_HZ,
                 backend_tls: ssl.SSLContext | None = None) -> None:
        self.scheduler = scheduler
        self.config = config
        self.link = McpLink(backend, clock=scheduler.clock, loop=scheduler, heartbeat_s=None,
                            name="backend", ssl_context=backend_tls)
        self.robot = RobotLink(self.link, perception.odometry, owner=OWNER)
        self.kit = Kit.build(self.robot, perception, config, localize=localize, detect=detect,
                             start_box=start_box)
        factories = {state: self._factory(cls) for state, cls in ACTIVITIES.items()}
        self.mission = Mission(Executive(factories), stop_robot=self.robot.stop_all,
                               config=MissionConfig.from_mapping(config.mission),
                               owner_name=OWNER)
        self.context = self.mission.context
        self.kit.tracker.bind(self.context)
        self.robot.on_owner = self.mission.observe_control
        self.robot.on_trip = self.mission.report_fault
        self.robot.on_foreign_owner = self._foreign_owner
        rate = scheduler.rate_hz
        self.tasks: list[ScheduledTask] = [
            scheduler.add_task("autonomy.mcp", scheduler.rate_at_most(LINK_HZ), self.link.tick),
            scheduler.add_task("autonomy.poll", min(rate, POLL_TASK_HZ), self.robot.tick),
            scheduler.add_task("autonomy.pose", mission_hz, self._pose_tick),
            scheduler.add_task("mission", mission_hz, self.mission.tick),
        ]

    def _factory(self, cls: type) -> Callable[[], Activity]:
        def make() -> Activity:
            activity: Activity = cls(self.kit)
            return activity
        return make

    def start(self, now: float) -> None:
        """Connect to the backend and start the run's clock (the first state acquires
        control once the link is up)."""
        self.link.start()
        self.mission.start(now)

    def close(self) -> None:
        """Remove the tasks and drop the link (the backend stops a feeder that goes)."""
        for task in self.tasks:
            self.scheduler.remove_task(task)
        self.tasks.clear()
        self.link.stop()

    # -- tasks ------------------------------------------------------------------------------
    def _pose_tick(self, now: float, dt: float) -> None:
        self.kit.tracker.tick(now, dt)
        load = self.robot.load_kg
        if math.isfinite(load) and self.mission.has_control:
            self.context.bin_kg = load

    def _foreign_owner(self, owner: str) -> None:
        self.kit.tracker.lose(f"{owner} had control and may have moved the robot",
                              keep_prior=False)
