"""The flight recorder wired into the supervisor (SPEC 8): its observer and its life.

`ramp run --record DIR` (or `ramp.yaml`'s `recorder:` block) makes a `Recorder`
(`recorder_for`) and hands it to `build(..., recorder=...)`, which connects a
`RecorderObserver` to the observer points and gives the supervisor the recorder: the
supervisor starts it before the buses open (so the modules' attachment is in the file),
samples `robot.get` and every module's get at 10 Hz from a scheduler task, reports
`robot:recorder.dropped=(n)` in `robot.get`, and closes it after the motors have stopped.

Everything here runs on the tick and only hands records to the recorder's bounded queue;
the recorder's writer thread does the file work (`ramp.recorder.writer`). Without a recorder
nothing here is imported and no hook is connected: recording off costs nothing.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import replace
from typing import TYPE_CHECKING

from ramp.config import Config
from ramp.layers.robot_distribution import Client
from ramp.mcp.messages import Request, Response
from ramp.mcp.protocol import TooLong, format_request
from ramp.recorder.config import RecorderConfig
from ramp.runtime.observers import Observer

if TYPE_CHECKING:
    from ramp.recorder.recorder import Recorder
    from ramp.runtime.supervisor import Supervisor

log = logging.getLogger("ramp.recorder")

#: How long shutdown waits for the writer to put the last records on the disk; systemd's
#: TimeoutStopSec (5 s) must leave room for it after the motors have stopped.
CLOSE_TIMEOUT_S = 2.0


def recorder_config(config: Config, record_dir: str | None) -> RecorderConfig | None:
    """What to record with: the config's `recorder:` block, its `dir` replaced by
    `--record DIR`; `--record` alone records with the block's defaults. None: off."""
    if record_dir is None:
        return config.recorder
    if config.recorder is None:
        return RecorderConfig(record_dir)
    return replace(config.recorder, dir=record_dir)


def recorder_for(config: Config, record_dir: str | None = None,
                 sim: bool = False) -> Recorder | None:
    """A recorder for `ramp run` (not started: the supervisor starts it), or None when
    recording is off. The MCAP writer is imported only here, only when recording."""
    rc = recorder_config(config, record_dir)
    if rc is None:
        return None
    from ramp import __version__
    from ramp.recorder.recorder import Recorder

    session = {"config": config.file, "ramp": __version__,
               "mode": "simulated (ramp run --sim)" if sim else "robot",
               "modules": ",".join(config.modules), "buses": ",".join(config.buses)}
    return Recorder(rc, session=session)


class RecorderObserver(Observer):
    """Turns the observer points into records (`ramp.recorder.schemas` lists the topics)."""

    def __init__(self, recorder: Recorder, outputs: Iterable[str] = ()) -> None:
        self.rec = recorder
        #: Labels of the digital outputs (LEDs, relays): their commands are not motion.
        self.outputs = frozenset(outputs)

    # -- the supervisor's life ----------------------------------------------------------------
    def started(self, supervisor: Supervisor) -> None:
        """Health and each module's get rows, sampled at 10 Hz by a scheduler task."""
        from ramp.recorder.recorder import SAMPLE_HZ

        rec = self.rec
        rec.add_rows_source("robot", supervisor.health_rows)
        for name in supervisor.slots:
            rec.add_rows_source(name, _module_rows(supervisor, name))
        sched = supervisor.scheduler
        divisor = max(1, round(sched.rate_hz / SAMPLE_HZ))
        sched.add_task("recorder", sched.rate_hz / divisor, rec.tick)
        host, port = supervisor.server.address
        rec.event(supervisor.clock.now(), "note",
                  f"serving on {host}:{port} ({supervisor.config.file})")

    def stopping(self, supervisor: Supervisor) -> None:
        rec = self.rec
        now = supervisor.clock.now()
        rec.tick(now, 0.0)  # the last state before the motors stop
        rec.event(now, "note", "shutting down: every motor to zero")

    # -- the request path ---------------------------------------------------------------------
    def message_in(self, t: float, client: Client, message: bytes | TooLong) -> None:
        if isinstance(message, TooLong):
            self.rec.mcp_in(t, client.peer, f"(discarded: {message.length} bytes, longer "
                                            "than server.max_line)")
        else:
            self.rec.mcp_in(t, client.peer, message)

    def message_out(self, t: float, client: Client, line: bytes) -> None:
        self.rec.mcp_out(t, client.peer, line)

    def command(self, t: float, bus: str, channel: str, value: float) -> None:
        self.rec.command(t, bus, channel, value,
                         "output" if channel in self.outputs else "motor")

    # -- the robot's events -------------------------------------------------------------------
    def module_state(self, t: float, module: str, state: str, reason: str) -> None:
        self.rec.module_state(t, module, state, reason)

    def interlock(self, t: float, name: str, active: bool, why: str) -> None:
        self.rec.event(t, "interlock", f"{name} {why}" if active else f"{name} released")

    def watchdog(self, t: float, state: str, why: str) -> None:
        if state == "tripped":
            self.rec.event(t, "watchdog_trip", f"every module stopped: {why}")
        else:
            self.rec.event(t, "watchdog", f"{state}: {why}")

    def audit(self, t: float, client: Client, request: Request, outcome: str) -> None:
        """Who asked what, and what came of it (SPEC 13): `IDENTITY PEER OUTCOME REQUEST`."""
        self.rec.event(t, "audit", f"{client.identity} {client.peer} {outcome} "
                                   f"{format_request(request)}")

    def control(self, t: float, owner: str, peer: str) -> None:
        text = f"released ({peer})" if owner == "none" else f"{owner} ({peer})"
        self.rec.event(t, "control", text)

    def stall(self, t: float, gap_s: float, unit: str) -> None:
        self.rec.event(t, "stall", f"tick loop stalled for {gap_s * 1e3:.0f} ms in {unit}: "
                                   "every module stopped")

    def bus_fault(self, t: float, bus: str, reason: str) -> None:
        self.rec.event(t, "fault", f"bus {bus}: {reason}")


def _module_rows(sup: Supervisor, name: str) -> Callable[[], list[Response]]:
    return lambda: sup.module_rows(name)
