"""What an activity answers each tick, and how the machine turns it into a trigger.

An activity (`ramp.statemachine.activity.Activity`) returns one `Status` from every `tick`:

    status                    trigger         meaning
    Status.running()          (none)          still working; tick me again
    Status.done(detail)       finished        the state's job is done
    Status.failed(reason)     failed          not this way: no path, off the path, the
                                              buttons never pressed
    Status.lost(reason)       lost            the pose cannot be trusted
    Status.operator(reason)   control_taken   someone else has control (`not_owner`)
    Status.fault(reason)      fault           the robot or the link failed: an MCP error,
                                              a `fault` answer, a watchdog trip
    Status.needs_operator(r)  needs_operator  a latched fault only an operator may clear
                                              (a stalled lift): stop and wait, no retry

`Status.from_mcp_error(code, detail)` maps an MCP error response to the right status, so
every activity treats `not_owner` (and `interlocked`: another module's state holds this one
back, SPEC 11) and `fault` the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class StatusKind(Enum):
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    LOST = "lost"
    OPERATOR = "operator"
    FAULT = "fault"
    NEEDS_OPERATOR = "needs_operator"


#: The machine's trigger for each status (RUNNING fires nothing).
TRIGGER_OF: dict[StatusKind, str] = {
    StatusKind.DONE: "finished",
    StatusKind.FAILED: "failed",
    StatusKind.LOST: "lost",
    StatusKind.OPERATOR: "control_taken",
    StatusKind.FAULT: "fault",
    StatusKind.NEEDS_OPERATOR: "needs_operator",
}


@dataclass(frozen=True)
class Status:
    """One activity tick's answer; `reason` ends up in the state-change log line."""

    kind: StatusKind
    reason: str = ""

    @classmethod
    def running(cls) -> Status:
        return _RUNNING

    @classmethod
    def done(cls, detail: str = "") -> Status:
        return cls(StatusKind.DONE, detail)

    @classmethod
    def failed(cls, reason: str) -> Status:
        return cls(StatusKind.FAILED, _need(reason))

    @classmethod
    def lost(cls, reason: str) -> Status:
        return cls(StatusKind.LOST, _need(reason))

    @classmethod
    def operator(cls, reason: str = "control taken") -> Status:
        return cls(StatusKind.OPERATOR, reason)

    @classmethod
    def fault(cls, reason: str) -> Status:
        return cls(StatusKind.FAULT, _need(reason))

    @classmethod
    def needs_operator(cls, reason: str) -> Status:
        return cls(StatusKind.NEEDS_OPERATOR, _need(reason))

    @classmethod
    def from_mcp_error(cls, code: str, detail: str = "") -> Status:
        """An MCP error response (`MODULE:DEVICE.error=(code,detail)`) as a status:
        `not_owner` is the operator taking over (SPEC 2.2), `interlocked` the same (the
        operator's setup holds the robot back, SPEC 11), anything else a fault."""
        text = f"{code}: {detail}" if detail else code
        if code in ("not_owner", "interlocked"):
            return cls.operator(text)
        return cls.fault(text)

    @property
    def trigger(self) -> str | None:
        """The machine trigger this status fires, None while running."""
        return TRIGGER_OF.get(self.kind)

    @property
    def is_running(self) -> bool:
        return self.kind is StatusKind.RUNNING

    def __str__(self) -> str:
        return f"{self.kind.value}({self.reason})" if self.reason else self.kind.value


def _need(reason: str) -> str:
    if not reason:
        raise ValueError("a failed, lost or fault status says why")
    return reason


_RUNNING = Status(StatusKind.RUNNING)
