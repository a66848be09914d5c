"""The executive's hands and eyes on the backend: commands and polls over one MCP link.

Everything the activities send to the robot goes through here, so three rules hold in one place:

- **The watchdog is fed only while the executive means to move** (`moving`). Drive commands go
  out at the control rate while driving and feed it by themselves; a lift or chain move feeds
  it with the polls, sent every `poll_moving_s` while `moving`. While nothing should move, the
  polls are spaced wider than the watchdog's timeout (`robot:watchdog.timeout`, read from
  `robot.get`), so they cannot keep a forgotten motion alive: the backend stops it. There is
  no heartbeat of the link's own (`McpLink(heartbeat_s=None)`): a stuck executive falls
  silent and the robot stops.
- **Every error answer is kept**, stamped with the activity it belongs to (`begin()` opens a
  new one), so an activity sees only its own: `problem()` turns the first into a `Status`
  (`not_owner` and `interlocked` -> operator, anything else -> fault). Answers to an
  earlier activity's commands are logged, not blamed on the next. A refusal by an interlock
  (`interlocked`, SPEC 11) is handled like `not_owner`: the executive stops meaning to move
  (the rule stopped what ran there) and says which rule refused what.
- **Odometry hears every drive and every stop** the executive sends, so dead reckoning
  matches what the wheels were told.

The polls (`robot:robot.get=()base:base.get=()ble:ble.get=()` in one message) keep `values`
(`"ble:load.kg" -> (12.3,)`), the control owner and the watchdog's state fresh; every owner
read goes to `on_owner` (the mission's `observe_control`), and a watchdog trip while the
executive meant to move goes to `on_trip` (the mission's `report_fault`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

from ramp.autonomy.mcp_link import McpLink
from ramp.autonomy.odometry import Odometry
from ramp.errors import ProtocolError
from ramp.mcp.session import Reply
from ramp.statemachine import Status

log = logging.getLogger("ramp.autonomy.executive")

POLL = "robot:robot.get=()base:base.get=()ble:ble.get=()"


class RobotLink:
    """Commands and polls for the activities; `tick` is a scheduler task."""

    def __init__(self, link: McpLink, odometry: Odometry | None = None, *,
                 owner: str = "autonomy", poll_moving_s: float = 0.2,
                 poll_idle_min_s: float = 0.5) -> None:
        self.link = link
        self.clock = link.clock
        self.odometry = odometry
        self.owner_name = owner
        self.poll_moving_s = poll_moving_s
        self.poll_idle_min_s = poll_idle_min_s
        self.moving = False  # the executive means to move: keep the watchdog fed
        self.values: dict[str, tuple[Any, ...]] = {}
        self.owner: str | None = None  # robot:control.owner as last read
        self.watchdog_state = ""
        self.watchdog_timeout = 1.0
        self.polled_at = -math.inf  # when the newest poll answer arrived
        self.on_owner: Callable[[str], None] | None = None
        self.on_trip: Callable[[str], None] | None = None
        self.on_foreign_owner: Callable[[str], None] | None = None
        self.sent = 0  # commands sent (not polls)
        self._gen = 0
        self._errors: list[tuple[int, str, str, str]] = []  # (gen, code, detail, request)
        self._poll_sent_at = -math.inf
        self._poll_in_flight = False
        self._answered_sent_at = -math.inf

    # -- the activity's slate -------------------------------------------------------------------
    def begin(self) -> None:
        """A new activity starts: earlier errors are no longer its business."""
        self._gen += 1
        self._errors.clear()

    def problem(self) -> Status | None:
        """The first error answer to this activity's commands, as a Status; a latched
        fault the backend reports (`ble:lift.stalled`) as one for the operator; None if
        none."""
        if self.value("ble:lift.stalled", 0.0) > 0.5:
            return Status.needs_operator(
                "the lift stalled (ble:lift.stalled): the mission stopped and waits for an "
                "operator to clear it with ble:lift.reset=() and release control")
        for gen, code, detail, request in self._errors:
            if gen == self._gen:
                return Status.from_mcp_error(code, f"{detail} (to {request})" if detail
                                             else f"to {request}")
        return None

    # -- commands ---------------------------------------------------------------------------
    def send(self, request: str, on_done: Callable[[bool], None] | None = None) -> bool:
        """Send a command; its error answers are kept for `problem()`. False when the link
        is down (then `problem()` says so too). `on_done(ok)` runs once it is settled: True
        for an answer with no error, False for an error answer or a lost connection."""
        gen = self._gen
        self.sent += 1

        def answered(reply: Reply[Any]) -> None:
            ok = self._check(reply, gen, request)
            if on_done is not None:
                on_done(ok)

        if not self.link.send(request, answered):
            self._errors.append((gen, "fault", f"not connected: {self.link.fault or 'link down'}",
                                 request))
            return False
        return True

    def drive(self, speed: int, direction: float) -> bool:
        """`base:base.drive=(speed,direction)` (SPEC 2.3), told to odometry too."""
        now = self.clock.now()
        self.moving = True
        if self.odometry is not None:
            self.odometry.command(now, speed, direction)
        return self.send(f"base:base.drive=({int(speed)},{direction:g})")

    def halt_base(self) -> bool:
        """Stop the wheels (the lift and chain keep what they do)."""
        if self.odometry is not None:
            self.odometry.stop(self.clock.now())
        return self.send("base:base.stop=()")

    def stop_all(self) -> None:
        """`robot:robot.stop=()`: the machine's stop. Accepted from anyone, always."""
        self.moving = False
        if self.odometry is not None:
            self.odometry.stop(self.clock.now())
        self.link.send("robot:robot.stop=()")

    def motion_stopped_by_others(self) -> None:
        """Someone else stopped the robot (an operator's acquire, a watchdog trip)."""
        self.moving = False
        if self.odometry is not None:
            self.odometry.stop(self.clock.now())

    # -- what the polls say ------------------------------------------------------------------
    def value(self, key: str, default: float = math.nan) -> float:
        """A number from the newest poll (`"ble:load.kg"`), `default` when unknown."""
        v = self.values.get(key)
        if not v or not isinstance(v[0], int | float):
            return default
        return float(v[0])

    @property
    def load_kg(self) -> float:
        return self.value("ble:load.kg")

    @property
    def lift_pos(self) -> float:
        return self.value("ble:lift.pos")

    @property
    def buttons(self) -> tuple[bool, bool]:
        return (self.value("base:l_button.press", 0.0) > 0.5,
                self.value("base:r_button.press", 0.0) > 0.5)

    def fresh(self, since: float) -> bool:
        """A poll sent at or after `since` has been answered."""
        return self._answered_sent_at >= since

    def poll_now(self) -> None:
        """Ask at the next tick instead of waiting for the period (a state just changed)."""
        self._poll_sent_at = -math.inf

    # -- the task ------------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        if not self.link.connected or self._poll_in_flight:
            return
        period = self.poll_moving_s if self.moving else max(self.poll_idle_min_s,
                                                            1.25 * self.watchdog_timeout)
        if now - self._poll_sent_at < period:
            return
        self._poll_sent_at = now
        self._poll_in_flight = True
        if not self.link.send(POLL, self._on_poll):
            self._poll_in_flight = False

    def _on_poll(self, reply: Reply[Any]) -> None:
        self._poll_in_flight = False
        if reply.sent_at is not None:
            self._answered_sent_at = reply.sent_at
        if reply.error is not None:
            return  # the link was lost: it says so itself, and the next command fails
        try:
            responses = reply.responses()
        except ProtocolError as exc:
            log.warning("robot link: unreadable poll answer: %s", exc)
            return
        self.polled_at = reply.received_at if reply.received_at is not None \
            else self.clock.now()
        old_watchdog = self.watchdog_state
        for r in responses:
            self.values[f"{r.module}:{r.device}.{r.prop}"] = r.values
        owner = self.values.get("robot:control.owner", ("",))[0]
        self.owner = str(owner)
        self.watchdog_state = str(self.values.get("robot:watchdog.state", ("",))[0])
        timeout = self.value("robot:watchdog.timeout")
        if math.isfinite(timeout) and timeout > 0:
            self.watchdog_timeout = timeout
        if self.owner not in (self.owner_name, "none", ""):
            self.motion_stopped_by_others()
            if self.on_foreign_owner is not None:
                self.on_foreign_owner(self.owner)
        if self.on_owner is not None and self.owner:
            self.on_owner(self.owner)
        if (self.watchdog_state == "tripped" and old_watchdog != "tripped"
                and self.owner == self.owner_name):
            was_moving = self.moving
            self.motion_stopped_by_others()
            if was_moving and self.on_trip is not None:
                self.on_trip("the backend's watchdog tripped: every module stopped")

    def _check(self, reply: Reply[Any], gen: int, request: str) -> bool:
        """Keep the reply's errors; True when it has none."""
        if reply.error is not None:
            self._errors.append((gen, "fault", reply.error, request))
            return False
        if not reply.line:
            return True
        try:
            responses = reply.responses()
        except ProtocolError as exc:
            self._errors.append((gen, "fault", f"unreadable answer: {exc}", request))
            return False
        ok = True
        for r in responses:
            if r.prop != "error":
                continue
            code = str(r.values[0]) if r.values else "fault"
            detail = str(r.values[1]) if len(r.values) > 1 else ""
            if gen != self._gen:
                log.info("robot link: late error to %s: %s %s", request, code, detail)
            self._errors.append((gen, code, detail, request))
            ok = False
            if code == "not_owner":
                self.motion_stopped_by_others()
            elif code == "interlocked":
                log.warning("robot link: %s refused by interlock %s", request,
                            detail.split(" ", 1)[0] or "?")
                self.motion_stopped_by_others()
        return ok
