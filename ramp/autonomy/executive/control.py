"""Acquire Control: take the robot as `autonomy` (SPEC 6.3), but never from an operator.

An acquire by a client that is not the owner succeeds even against another owner (that is how
an operator overrides the autonomy, SPEC 2.2), so the autonomy asks only once a fresh
`robot.get` shows nobody holding control (or itself): an operator who holds it keeps it, and
the activity says `operator` (the mission waits, paused, until control is free).
"""

from __future__ import annotations

from ramp.autonomy.executive.step import Step
from ramp.statemachine import Status


class AcquireControl(Step):
    def begin(self, now: float) -> None:
        self.asked = False
        self.acquired = False
        self.since = now
        self.kit.robot.poll_now()

    def step(self, now: float, dt: float) -> Status:
        robot = self.kit.robot
        if not robot.link.connected:
            return Status.running()  # the link reconnects; the state's time-out bounds it
        if not self.asked:
            if not robot.fresh(self.since):
                return Status.running()
            owner = robot.owner or "none"
            if owner not in ("none", robot.owner_name):
                return Status.operator(f"{owner} holds control")
            self.asked = robot.send(f"robot:control.acquire=({robot.owner_name})",
                                    on_done=self._done)
            return Status.running()
        if self.acquired:
            robot.motion_stopped_by_others()  # an acquire stops all motion first
            return Status.done(f"control acquired as {robot.owner_name}")
        return Status.running()

    def _done(self, ok: bool) -> None:
        """An acquire answered without error is control held; one lost with the link or
        refused is asked again (the state's time-out bounds the asking)."""
        if ok:
            self.acquired = True
        else:
            self.asked = False
