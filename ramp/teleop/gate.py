"""The motion gate: no motion goes on after a stop the operator did not cause. Sans-IO.

The console sends motion only when the operator's input changes, and a real stick changes
all the time (±0.005 is enough for a new `base.drive`). Without a gate, a stop that came
from elsewhere — a supervisor stall, a watchdog trip, another client's `robot.stop`, a
takeover handed back — was followed within a frame by the console's next change, and the
robot drove on with the dead-man never released.

The robot's polls cannot tell which came first (polls and commands use two connections), so
the question is asked on the command connection itself, where answers keep their order:
while this console has motion going, each new motion message is held and `robot.get` is
sent first. Its `watchdog.state` is `armed` as long as our motion runs; `idle` or `tripped`
means something stopped it since our last message. Then the held message is dropped and the
controller latches driving until the dead-man is released and pressed again. Messages that
arrive while a probe is out are merged into the held one (the newest value of each request
wins). A stop cancels whatever is held and is never delayed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ramp.mcp.messages import Request, Response

PROBE = "robot:robot.get=()"
Message = list[Request]


def is_stop_only(message: Message) -> bool:
    return bool(message) and all(r.function == "stop" for r in message)


def moves(r: Request) -> bool:
    """Whether a motion request sets its target moving: a first parameter that is not zero
    (a speed, a position), or no parameter at all (`lift.extend`)."""
    if not r.params:
        return True
    try:
        return float(r.params[0]) != 0.0
    except ValueError:
        return True


def merge(held: Message, newer: Message) -> Message:
    """`held` then `newer`, a request of `held` dropped when `newer` sets the same target."""
    targets = {(r.module, r.device, r.function) for r in newer}
    return [r for r in held if (r.module, r.device, r.function) not in targets] + newer


def stopped_by_someone(rows: list[Response]) -> str:
    """Why a probe's `robot.get` says our motion no longer runs, or "" when it still may."""
    for r in rows:
        if (r.module, r.device, r.prop) == ("robot", "watchdog", "state") and r.values:
            state = str(r.values[0])
            if state == "tripped":
                return "the robot's watchdog tripped (a stall or a silent client)"
            if state == "idle":
                return "the robot was stopped by someone else"
            return ""
    return ""


@dataclass
class MotionGate:
    """The gate's state: what is held while a probe is out, and whether ours is moving."""

    #: Each target we sent motion to: whether our last request there set it moving.
    targets: dict[tuple[str, str, str], bool] = field(default_factory=dict)
    held: Message | None = None
    probing: bool = False
    probes: int = field(default=0)

    def offer(self, message: Message) -> tuple[Message | None, bool]:
        """A message to send: (what to send now, whether to send a probe first).

        Heartbeats and stops go at once (a stop also drops what is held); motion goes at
        once when nothing of ours is moving, and is held behind a probe otherwise."""
        if not message:
            return message, False
        if is_stop_only(message):
            self.cancel()
            return message, False
        if self.probing:
            self.held = merge(self.held or [], message)
            return None, False
        if not self.moving:
            self.sent(message)
            return message, False
        self.held, self.probing = message, True
        self.probes += 1
        return None, True

    @property
    def moving(self) -> bool:
        """Something we set moving has not been stopped (so a stop since is not ours)."""
        return any(self.targets.values())

    def sent(self, message: Message) -> None:
        for r in message:
            if r.function == "stop":
                for key in [k for k in self.targets if k[0] == r.module or r.module == "robot"]:
                    self.targets[key] = False
            else:
                self.targets[(r.module, r.device, r.function)] = moves(r)

    def forget(self, modules: set[str]) -> None:
        """The robot refused our motion there (not_owner, fault, interlocked): it never
        moved, so a stop seen later is not a stop of ours."""
        for key in self.targets:
            if key[0] in modules:
                self.targets[key] = False

    def answered(self, rows: list[Response] | None) -> tuple[Message | None, str]:
        """The probe's answer (None: it failed): (the held message to send now, or why it
        is dropped)."""
        held, self.held, self.probing = self.held, None, False
        if held is None:
            return None, ""
        if rows is None:
            return None, "no answer to the check before motion"
        why = stopped_by_someone(rows)
        if why:
            self.targets.clear()
            return None, why
        self.sent(held)
        return held, ""

    def cancel(self) -> None:
        """A stop, an interruption or a lost link: nothing held goes out, nothing moves."""
        self.held, self.probing = None, False
        self.targets.clear()
