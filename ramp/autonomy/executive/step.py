"""The template every activity of the executive follows (`ramp.statemachine.Activity`).

`start` opens a new slate on the robot link (errors to earlier commands are not this one's),
`tick` answers the first MCP error to this activity's commands before anything else
(`not_owner` -> operator, anything else -> fault), and `stop` stops feeding the watchdog: the
machine sends the stop itself when the robot must stop. Subclasses write `begin`, `step` and,
when they hold something, `end`.
"""

from __future__ import annotations

from ramp.autonomy.executive.kit import Kit
from ramp.statemachine import MissionContext, Status


class Step:
    """Base of the executive's activities; see the module docstring."""

    def __init__(self, kit: Kit) -> None:
        self.kit = kit
        self.ctx = MissionContext()
        self.started_at = 0.0

    # -- the Activity protocol ------------------------------------------------------------------
    def start(self, ctx: MissionContext, now: float) -> None:
        self.ctx = ctx
        self.started_at = now
        self.kit.robot.begin()
        self.begin(now)

    def tick(self, now: float, dt: float) -> Status:
        problem = self.kit.robot.problem()
        if problem is not None:
            return problem
        return self.step(now, dt)

    def stop(self) -> None:
        self.kit.robot.moving = False
        self.end()

    # -- what subclasses write ------------------------------------------------------------------
    def begin(self, now: float) -> None:
        """The state was entered."""

    def step(self, now: float, dt: float) -> Status:
        raise NotImplementedError

    def end(self) -> None:
        """The state is left (for any reason); send no command."""
