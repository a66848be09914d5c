"""What the console's command connection sends, and when: the safety gate, sans-IO.

Everything here is decided from events and a time passed in, so the rules are tested on a
virtual clock; the asyncio side only delivers events and writes the messages `tick` returns.

The rules (SPEC 7, and teleop_twist_joy's dead-man habit):
- Motion goes out only for a page that is connected, fresh (its last message is at most
  `stale_after` old) and focused (or out of focus for at most `focus_grace`).
- The dead-man (the pad's enable button, or a held drive key) gates every motion. While it is
  held, a binding's request is sent when its value changes; a binding still at rest sends
  nothing, so holding the dead-man alone never fights another client.
- Releasing it sends one message of module stops for what this console moved, then silence:
  no stream of zeros, no heartbeats.
- While this console has motion outstanding (sent and not yet stopped), it sends a heartbeat
  every `heartbeat_period` so the robot's watchdog stays fed, and only while the page that
  commanded it is live. When that page closes, stalls or stays out of focus too long, the
  module stops go out once and the heartbeats end, so the robot's own watchdog covers a
  console that then dies.
- After an interruption (STOP, lost robot link, watchdog trip, the page going stale) a
  dead-man still held does nothing until it is released and pressed again: motion never
  resumes by itself.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from ramp.mcp.messages import Request
from ramp.teleop.mapping import IDLE, Intent

#: One message for the command connection; an empty list is a heartbeat.
Message = list[Request]

STALE_AFTER = 0.3
FOCUS_GRACE = 0.3
HEARTBEAT_PERIOD = 0.1


def module_stop(module: str) -> Request:
    """`MODULE:MODULE.stop=()`, the stop every RAMP module offers (SPEC 2.1)."""
    return Request(module, module, "stop")


@dataclass
class PageState:
    """What the controller knows about one open page."""

    seen: float
    focused: bool = True
    blur_since: float | None = None
    intent: Intent = IDLE
    engaged: bool = False
    #: The dead-man was held through an interruption: ignored until released.
    latched: bool = False
    presses: frozenset[tuple[str, tuple[str, ...]]] = frozenset()
    note: str = ""


@dataclass
class Controller:
    """The motion state of one `ramp-teleop`: which page drives, what was sent, what to stop."""

    stop_for: Callable[[str], Request] = module_stop
    stale_after: float = STALE_AFTER
    focus_grace: float = FOCUS_GRACE
    heartbeat_period: float = HEARTBEAT_PERIOD
    link_up: bool = False
    pages: dict[str, PageState] = field(default_factory=dict)
    #: The page whose motion is outstanding or who holds the dead-man.
    driver: str | None = None
    #: Modules this console moved since it last stopped them, in the order it moved them.
    touched: dict[str, None] = field(default_factory=dict)
    #: The engagement's continuous requests as last sent: target -> params.
    sent: dict[str, tuple[str, ...]] = field(default_factory=dict)
    engaged_source: str = ""
    last_sent_at: float = float("-inf")
    #: When the last motion request went out (heartbeats aside).
    last_motion_at: float = float("-inf")

    # -- events ---------------------------------------------------------------------------------
    def open_page(self, page: str, now: float) -> None:
        self.pages[page] = PageState(seen=now)

    def close_page(self, page: str, now: float) -> None:
        """The page's connection ended; the next `tick` stops what it drove."""
        state = self.pages.get(page)
        if state is not None:
            state.seen = float("-inf")  # never fresh again
            state.intent = IDLE

    def forget_page(self, page: str) -> None:
        if page != self.driver:
            self.pages.pop(page, None)

    def page_input(self, page: str, now: float, *, focused: bool, intent: Intent) -> None:
        """A message from the page: it is alive, and this is what its operator asks for."""
        state = self.pages.get(page)
        if state is None:
            return
        state.seen = now
        if focused:
            state.blur_since = None
        elif state.focused or state.blur_since is None:
            state.blur_since = now
        state.focused = focused
        state.intent = intent

    def seen(self, page: str, now: float, *, focused: bool | None = None) -> None:
        """Any other message from the page also proves it is alive."""
        state = self.pages.get(page)
        if state is None:
            return
        state.seen = now
        if focused is not None:
            self.page_input(page, now, focused=focused, intent=state.intent)

    def commanded(self, page: str, modules: Iterable[str], now: float) -> None:
        """The console sent a motion request typed on `page` (not through `tick`)."""
        for m in modules:
            self.touched.setdefault(m)
        if self.driver is None and page in self.pages:
            self.driver = page
        self.last_sent_at = self.last_motion_at = now

    def forget(self, modules: Iterable[str]) -> None:
        """Nothing of ours is moving on these modules: the robot refused our motion there
        (not_owner, fault) or the operator stopped them. A stop for a refused module would
        halt whoever does own that motion (the autonomy, say)."""
        for m in modules:
            self.touched.pop(m, None)

    def halt(self, now: float, reason: str) -> list[Message]:
        """End any engagement now (a profile switch, shutting down): stops for what moved."""
        out = self._stop_touched()
        self._end_engagement(reason)
        if out:
            self.last_sent_at = now
        return out

    def interrupted(self, now: float, reason: str) -> None:
        """The robot was stopped (STOP, control taken, watchdog trip): latch, forget, be quiet."""
        self.touched.clear()
        self._end_engagement(reason)

    def set_link(self, up: bool, now: float) -> None:
        """The command connection came up or was lost; a loss is an interruption."""
        if self.link_up and not up:
            self.interrupted(now, "robot link lost")
        self.link_up = up

    # -- queries --------------------------------------------------------------------------------
    def live(self, page: str, now: float) -> bool:
        state = self.pages.get(page)
        if state is None or now - state.seen > self.stale_after:
            return False
        return state.blur_since is None or now - state.blur_since <= self.focus_grace

    def why_not_live(self, page: str, now: float) -> str:
        state = self.pages.get(page)
        if state is None or state.seen == float("-inf"):
            return "page closed"
        if now - state.seen > self.stale_after:
            return "page stalled"
        if state.blur_since is not None and now - state.blur_since > self.focus_grace:
            return "page lost focus"
        return ""

    def page_view(self, page: str, now: float) -> dict[str, object]:
        """The drive state one page shows its operator."""
        state = self.pages.get(page)
        if state is None:
            return {}
        return {
            "live": self.live(page, now),
            "engaged": state.engaged,
            "latched": state.latched,
            "driver": self.driver == page,
            "source": self.engaged_source if state.engaged else state.intent.source,
            "enable": state.intent.enable,
            "outstanding": sorted(self.touched) if self.driver == page else [],
            "note": state.note,
        }

    # -- the tick -------------------------------------------------------------------------------
    def tick(self, now: float) -> list[Message]:
        """Messages to send now, in order."""
        out: list[Message] = []
        for page, state in list(self.pages.items()):
            live = self.live(page, now)
            if not state.intent.enable:
                state.latched = False
                state.note = ""
            if not live:
                if state.intent.enable:
                    state.latched = True
                if page == self.driver:
                    out += self._stop_touched()
                    self._end_engagement(self.why_not_live(page, now))
                    state.note = self.why_not_live(page, now)
                if state.seen == float("-inf"):
                    del self.pages[page]
                continue
            if state.engaged and (not state.intent.enable
                                  or state.intent.source != self.engaged_source):
                out += self._stop_touched()
                state.engaged = False
                self.sent.clear()
                self.engaged_source = ""
            if state.intent.enable and not state.engaged and not state.latched:
                if not self.link_up:
                    state.note = "robot link down"
                elif self.driver not in (None, page):
                    state.note = "another console page is driving"
                else:
                    state.engaged = True
                    state.note = ""
                    self.driver = page
                    self.engaged_source = state.intent.source
            if state.engaged:
                message = self._changes(state)
                if message:
                    out.append(message)
            state.presses = state.intent.presses
        if self.driver is not None:
            driver = self.pages.get(self.driver)
            if driver is None or (not driver.engaged and not self.touched):
                self.driver = None
        if out:
            self.last_sent_at = now
            if any(r.function != "stop" for m in out for r in m):
                self.last_motion_at = now
        elif self.touched and self.driver is not None and self.link_up \
                and now - self.last_sent_at >= self.heartbeat_period:
            out.append([])
            self.last_sent_at = now
        return out

    # -- internals ------------------------------------------------------------------------------
    def _changes(self, state: PageState) -> Message:
        message: Message = []
        for target, output in state.intent.outputs.items():
            before = self.sent.get(target)
            if before == output.params or (before is None and output.at_rest):
                continue
            message.append(_request(target, output.params))
            self.sent[target] = output.params
        for target, params in sorted(state.intent.presses - state.presses):
            message.append(_request(target, params))
        for r in message:
            self.touched.setdefault(r.module)
        return message

    def _stop_touched(self) -> list[Message]:
        if not self.touched or not self.link_up:
            self.touched.clear()
            return []
        message = [self.stop_for(m) for m in self.touched]
        self.touched.clear()
        return [message]

    def _end_engagement(self, reason: str) -> None:
        for state in self.pages.values():
            if state.engaged or state.intent.enable:
                state.latched = state.intent.enable
                state.note = reason if state.intent.enable else state.note
            state.engaged = False
        self.sent.clear()
        self.engaged_source = ""
        self.driver = None


def _request(target: str, params: tuple[str, ...]) -> Request:
    module, rest = target.split(":", 1)
    device, function = rest.split(".", 1)
    return Request(module, device, function, params)
