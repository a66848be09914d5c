"""What the running supervisor tells an observer: the flight recorder, a benchmark, a tool.

One method per point of the request path and the robot's life. Every method does nothing
here; `ramp.runtime.build` connects to the layers only the methods a subclass overrides, so
a point nobody observes keeps its hook at None and costs one attribute test.

The points (method, when, and the layer hook it is connected to):

- `message_in(t, client, message)`: a complete MCP message taken up, as it arrived (bytes
  without `\\n`, or `TooLong`); `McpServer.on_message_in`.
- `message_out(t, client, line)`: its one answer line (without `\\n`);
  `McpServer.on_message_out`.
- `command(t, bus, channel, value)`: a command handed to a driver (`channel` is
  `module.device`; a duty, or 0/1 for an output); `Bus.on_command`.
- `module_state(t, module, state, reason)`: a module attached, or faulted (its motion
  stopped); `ModuleSlot.on_change`.
- `watchdog(t, state, why)`: the watchdog armed, disarmed, tripped (`why`: motion, expired,
  commander lost, tick loop stalled ...); `Watchdog.on_change`.
- `control(t, owner, peer)`: control acquired, released, taken over;
  `RobotDistribution.on_control`.
- `interlock(t, name, active, why)`: an interlock rule became active (or released);
  `Interlocks.on_change`.
- `stall(t, gap_s, unit)`: the loop stalled and every module was stopped first; the
  supervisor's stall handler.
- `bus_fault(t, bus, reason)`: a bus failed and was closed (its modules fault);
  `BusManager.on_fault`.
- `tick(t, late_s)`: every tick, with how late it started; `Scheduler.on_tick`.
- `tick_done(t, busy_s)`: every tick, with how long its tasks took; `Scheduler.on_tick_done`.
- `started(supervisor)`: serving; add periodic work here (`supervisor.scheduler.add_task`),
  such as health and module rows at 10 Hz from `supervisor.health_rows()` and
  `supervisor.module_rows(name)`.
- `stopping(supervisor)`: at shutdown, before the motors stop and the buses close.

Times are the supervisor's clock (`t`, seconds), as its tasks see it.

Several observers at once (the flight recorder and a benchmark's, say): `fan_out(a, b)`
makes one that calls, at each point, only those of them that override it, in order.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ramp.layers.robot_distribution import Client
from ramp.mcp.messages import Request
from ramp.mcp.protocol import TooLong

if TYPE_CHECKING:
    from ramp.runtime.supervisor import Supervisor

#: The methods `build` connects when a subclass overrides them.
POINTS = ("message_in", "message_out", "command", "module_state", "watchdog", "control",
          "interlock", "audit", "stall", "bus_fault", "tick", "tick_done")


class Observer:
    """Override the points you want; see the module docstring."""

    def started(self, supervisor: Supervisor) -> None:
        """Serving now."""

    def stopping(self, supervisor: Supervisor) -> None:
        """About to stop every motor and close everything."""

    def message_in(self, t: float, client: Client, message: bytes | TooLong) -> None:
        """A complete message, as it arrived (without its `\\n`)."""

    def message_out(self, t: float, client: Client, line: bytes) -> None:
        """The one answer line of a message (without its `\\n`)."""

    def command(self, t: float, bus: str, channel: str, value: float) -> None:
        """A command handed to a driver."""

    def module_state(self, t: float, module: str, state: str, reason: str) -> None:
        """A module's attachment changed."""

    def watchdog(self, t: float, state: str, why: str) -> None:
        """The watchdog changed state."""

    def control(self, t: float, owner: str, peer: str) -> None:
        """Control changed hands (`owner` is `none` once released)."""

    def interlock(self, t: float, name: str, active: bool, why: str) -> None:
        """An interlock rule became active or was released."""

    def audit(self, t: float, client: Client, request: Request, outcome: str) -> None:
        """A state-changing request, "accepted" or refused (its error code), and who sent
        it (SPEC 13: `client.identity`, `client.peer`)."""

    def stall(self, t: float, gap_s: float, unit: str) -> None:
        """The loop lost `gap_s` in `unit`; every module has been stopped."""

    def bus_fault(self, t: float, bus: str, reason: str) -> None:
        """A bus failed and was closed; it is retried about once a second."""

    def tick(self, t: float, late_s: float) -> None:
        """A tick began `late_s` after its deadline."""

    def tick_done(self, t: float, busy_s: float) -> None:
        """The tick that began at `t` took `busy_s` (its tasks and their bookkeeping)."""


def overridden(observer: Observer, point: str) -> bool:
    """True when `observer` does something at `point` (its class overrides the method, or,
    for a fan-out, one of its observers does)."""
    if isinstance(observer, FanOut):
        return bool(observer.at[point])
    return getattr(type(observer), point) is not getattr(Observer, point)


class FanOut(Observer):
    """Several observers as one: each point calls the observers that override it, in the
    order given. A point none of them overrides stays unconnected (`overridden` is False),
    so it costs nothing, as with a single observer."""

    def __init__(self, observers: tuple[Observer, ...]) -> None:
        self.observers = observers
        self.at: dict[str, tuple[Callable[..., Any], ...]] = {
            point: tuple(getattr(o, point) for o in observers if overridden(o, point))
            for point in POINTS}

    def _call(self, point: str, *args: Any) -> None:
        for method in self.at[point]:
            method(*args)

    def started(self, supervisor: Supervisor) -> None:
        for o in self.observers:
            o.started(supervisor)

    def stopping(self, supervisor: Supervisor) -> None:
        for o in self.observers:
            o.stopping(supervisor)

    def message_in(self, t: float, client: Client, message: bytes | TooLong) -> None:
        self._call("message_in", t, client, message)

    def message_out(self, t: float, client: Client, line: bytes) -> None:
        self._call("message_out", t, client, line)

    def command(self, t: float, bus: str, channel: str, value: float) -> None:
        self._call("command", t, bus, channel, value)

    def module_state(self, t: float, module: str, state: str, reason: str) -> None:
        self._call("module_state", t, module, state, reason)

    def watchdog(self, t: float, state: str, why: str) -> None:
        self._call("watchdog", t, state, why)

    def control(self, t: float, owner: str, peer: str) -> None:
        self._call("control", t, owner, peer)

    def interlock(self, t: float, name: str, active: bool, why: str) -> None:
        self._call("interlock", t, name, active, why)

    def audit(self, t: float, client: Client, request: Request, outcome: str) -> None:
        self._call("audit", t, client, request, outcome)

    def stall(self, t: float, gap_s: float, unit: str) -> None:
        self._call("stall", t, gap_s, unit)

    def bus_fault(self, t: float, bus: str, reason: str) -> None:
        self._call("bus_fault", t, bus, reason)

    def tick(self, t: float, late_s: float) -> None:
        self._call("tick", t, late_s)

    def tick_done(self, t: float, busy_s: float) -> None:
        self._call("tick_done", t, busy_s)


def fan_out(*observers: Observer | None) -> Observer | None:
    """One observer for all those given (None ones left out): None, the only one, or a
    `FanOut`."""
    present = tuple(o for o in observers if o is not None)
    if not present:
        return None
    return present[0] if len(present) == 1 else FanOut(present)
