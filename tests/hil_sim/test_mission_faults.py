"""Latched faults in a whole mission: a lift jammed during a dig (`sim:lift.jam=(1)`, SPEC
12) latches `ble:lift.stalled` when the lift next moves; the mission stops and waits for the
operator, saying why, and never clears the fault itself (no `ble:lift.reset`)."""

from __future__ import annotations

from typing import Any

import pytest

from ramp.autonomy.mcp_link import McpLink
from ramp.simulation.campaign import combination
from ramp.simulation.mission import MissionOptions, MissionRun


class Jammer:
    """Jams the lift a few seconds into the first dig: `sim:lift.jam=(1)` over MCP, on the
    connection that holds control (a `state` function needs it; a second client taking
    control would pause the mission instead)."""

    def __init__(self) -> None:
        self.link: McpLink | None = None
        self.jammed_at: float | None = None
        self.seen_waiting_at: float | None = None
        self.replies: list[bytes] = []

    def sampled(self, run: MissionRun, now: float) -> None:
        assert run.autonomy is not None and run.rig is not None
        state = run.autonomy.mission.state
        if self.link is None and state == "excavate":
            self.link = run.autonomy.robot.link
            self.jammed_at = now + 5.0  # the ladder is down, the chain digging
        elif self.link is not None and self.jammed_at is not None and now >= self.jammed_at \
                and self.seen_waiting_at is None:
            self.link.send("sim:lift.jam=(1)", lambda reply: self.replies.append(reply.line))
            self.seen_waiting_at = -1.0
        elif state == "waiting_for_operator" and self.seen_waiting_at == -1.0:
            self.seen_waiting_at = now
        elif self.seen_waiting_at is not None and self.seen_waiting_at > 0 \
                and now > self.seen_waiting_at + 10.0:
            run.request_stop()


@pytest.mark.timeout(180)
def test_a_lift_jammed_during_a_dig_stops_the_mission_to_wait_for_the_operator() -> None:
    box, heading = combination(0)
    run = MissionRun(MissionOptions(seed=0, start_box=box, heading=heading, duration=300))
    jammer = Jammer()
    run.observers.append(jammer)
    sent: list[str] = []
    run.build()
    assert run.autonomy is not None
    link: Any = run.autonomy.robot.link
    original = link.send

    def spy(request: str, *args: Any, **kwargs: Any) -> Any:
        sent.append(request)
        return original(request, *args, **kwargs)

    link.send = spy
    summary = run.run()
    assert jammer.replies == [b""], jammer.replies  # the jam was accepted
    assert summary["outcome"] == "waiting_for_operator", summary
    path = [c.dest for c in run.changes]
    assert path[-1] == "waiting_for_operator"
    # The dig goes on with the ladder down (a jammed screw holds it there); the stall latches
    # when the deposit drives the lift, and the mission goes straight to the operator: no
    # retry of a latched fault, no reset of its own.
    assert "excavate" in path and path[-2] == "deposit"
    assert "lift stalled" in run.changes[-1].reason
    assert not any("lift.reset" in r for r in sent)
    assert summary["collisions"] == 0 and summary["crater_entries"] == 0
