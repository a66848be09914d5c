"""How a built supervisor runs as the robot's service: the one function `ramp run` and the
realtime mission's backend process (`ramp.simulation.backend_process`) both run it with, so
the figures a simulated realtime run gives are the robot's.

`serve` does, in order: the stop signals (every one stops every motor first, then the
process ends with status 0), the service's scheduling priority where permitted (SCHED_FIFO
at `scripts/ramp.service`'s priority; under systemd the unit has already set it, and a
process without the right keeps its own), `Supervisor.start`, the stall guard's thread
(SPEC 2.2), systemd's notifier, `Supervisor.settle`, `gc.freeze()` of everything built so
far, the ready announcement, the loop until a stop, and the shutdown (zeros on every wire).
"""

from __future__ import annotations

import gc
import logging
import os
import signal
from collections.abc import Callable
from dataclasses import dataclass
from types import FrameType
from typing import TYPE_CHECKING

from ramp.common.hostport import format_hostport

if TYPE_CHECKING:
    from ramp.runtime.supervisor import Supervisor

log = logging.getLogger("ramp")

#: Signals that stop every motor (zeros on the wire), then end the service with status 0.
STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP,
                                            signal.SIGQUIT)
#: `CPUSchedulingPriority` of `scripts/ramp.service` (SCHED_FIFO): the tick loop's priority
#: on the robot.
SERVICE_RT_PRIORITY = 20


@dataclass
class ServiceState:
    """What `serve` set up, for the ready announcement and the tests: the scheduling policy
    the loop runs under, whether the stall guard's thread runs, how many objects
    `gc.freeze()` took out of the collector's passes."""

    policy: str = ""
    stall_guard: bool = False
    gc_frozen: int = 0


def scheduling_priority(priority: int | None) -> str:
    """Run this process under SCHED_FIFO at `priority` where permitted (None: leave it);
    the policy it runs under, in words. A process already real-time (systemd's unit) keeps
    its own; one without the right (no CAP_SYS_NICE, RLIMIT_RTPRIO too low, a kernel with RT
    group scheduling) keeps the default, which is said, not an error."""
    if not hasattr(os, "sched_setscheduler"):
        return "default (no POSIX scheduling on this platform)"
    current = os.sched_getscheduler(0)
    if current in (os.SCHED_FIFO, os.SCHED_RR):
        name = "fifo" if current == os.SCHED_FIFO else "rr"
        return f"{name} {os.sched_getparam(0).sched_priority} (set before start)"
    if priority is None:
        return "default"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        log.info("the tick loop runs at the default priority: SCHED_FIFO %d not permitted "
                 "(%s)", priority, exc.strerror)
        return f"default (fifo {priority} not permitted)"
    return f"fifo {priority}"


def serve(sup: Supervisor, *, ready: Callable[[ServiceState], None],
          until: Callable[[], bool] | None = None, rt_priority: int | None = None,
          stop_signals: tuple[signal.Signals, ...] = STOP_SIGNALS,
          on_stop: Callable[[], None] | None = None,
          on_start_failed: Callable[[Exception], None] | None = None) -> int:
    """Start `sup` and run it as the robot's service until a stop signal (or `until()`);
    every motor is stopped before this returns. `ready(state)` announces it once it serves
    (never after a stop signal during start-up). `on_stop` runs after the shutdown, even on
    a failed start, after `on_start_failed(exc)`. 0, or 1 when it could not start."""
    from ramp.runtime.systemd import SystemdNotifier

    state = ServiceState()
    notifier = SystemdNotifier()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        log.info("%s received: stopping every motor and exiting", signal.Signals(signum).name)
        sup.scheduler.stop()

    # SIGHUP (the terminal or SSH session went away) and SIGQUIT (Ctrl-backslash) used to end
    # the process with the motors still commanded: every one of them stops the robot first.
    for signum in stop_signals:
        signal.signal(signum, on_signal)
    state.policy = scheduling_priority(rt_priority)
    try:
        sup.start()
    except Exception as exc:  # noqa: BLE001 - whatever failed, the motors must be stopped
        if isinstance(exc, OSError):
            log.error("cannot serve on %s: %s",
                      format_hostport(sup.server.host, sup.server.port), exc.strerror)
        else:
            log.exception("start-up failed")
        sup.shutdown()
        if on_start_failed is not None:
            on_start_failed(exc)
        if on_stop is not None:
            on_stop()
        return 1
    guard = sup.stall_guard
    guard.start()
    state.stall_guard = guard.running
    notifier.attach(sup)
    sup.settle()
    # Everything built so far lives as long as the process: take it out of the garbage
    # collector's full passes, which would otherwise walk it (7 ms here) in the middle of a
    # tick now and then.
    gc.freeze()
    state.gc_frozen = gc.get_freeze_count()
    if not sup.scheduler.stopping:  # a signal during start-up: never announce ready
        ready(state)
        h, p = sup.server.address
        notifier.ready(f"serving on {format_hostport(h, p)}")
    try:
        sup.scheduler.run(until)
    finally:
        notifier.stopping()
        guard.stop()
        sup.shutdown()
        if on_stop is not None:
            on_stop()
    return 0
