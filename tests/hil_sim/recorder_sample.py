"""A short simulated MARTE run, recorded from outside the supervisor: the README's sample.

    .venv/bin/python -m tests.hil_sim.recorder_sample DIR    # prints the MCAP file's path

The supervisor (the MARTE config on the physics model, wire-level Sabertooth emulators, a
virtual clock: `tests.harness.SimHarness`) does not feed the recorder itself yet, so
`OutsideFeed` does what the supervisor's hooks will do, from outside: the MCP lines of every
client as they go in and come back, `robot.get` and each module's get polled over MCP at
10 Hz, module state changes and watchdog and control events as those polls show them, every
command handed to a driver (each motor channel's `set_duty`, wrapped), and the supervisor's
log at WARNING and above.

The run (32 s): an operator takes control, drives MARTE into the digging region, turns a
little, digs with the chain, then goes silent, so the watchdog trips; comes back, raises the
bin, backs out and gives control up. A shell client meanwhile sends a bad request and is
refused a command while the operator owns control.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ramp.mcp.protocol import parse_response_line
from ramp.recorder import Recorder, RecorderConfig
from tests.harness import SimHarness, TestClient

ORIGIN_NS = 1_779_285_600_000_000_000  # 2026-05-20 14:00:00 UTC, a made-up run date
DT = 0.05                              # s of simulated time per step
DURATION = 32.0


class OutsideFeed:
    """Feeds `rec` from outside a running supervisor (see the module's docstring)."""

    def __init__(self, h: SimHarness, rec: Recorder) -> None:
        self.h = h
        self.rec = rec
        self.watchdog = "idle"
        self.owner = "none"
        self.states: dict[str, str] = {}
        self.handler = rec.log_handler(h.clock.now)
        logging.getLogger("ramp").addHandler(self.handler)
        for bus in h.sup.buses.values():
            for motor in bus.motors:
                motor.set_duty = self._tap(bus.name, motor.label, motor.set_duty)  # type: ignore[method-assign]
        self.monitor = self.client()

    def _tap(self, bus: str, label: str,
             set_duty: Callable[[float], None]) -> Callable[[float], None]:
        def tapped(duty: float) -> None:
            set_duty(duty)
            self.rec.command(self.h.clock.now(), bus, label, duty)
        return tapped

    def client(self) -> RecordedClient:
        c = RecordedClient(self.h, self.rec)
        self.h.clients.append(c)
        return c

    def poll(self) -> None:
        """One 10 Hz sample: health and every module's get, and what changed."""
        t = self.h.clock.now()
        rows = parse_response_line(self.monitor.ask(
            "robot:robot.get=()base:base.get=()ble:ble.get=()").encode())
        by_module: dict[str, list[Any]] = {}
        for r in rows:
            by_module.setdefault(r.module, []).append(r)
        self.rec.health(t, by_module.pop("robot", []))
        for module, module_rows in by_module.items():
            self.rec.module_rows(t, module, module_rows)
        for r in rows:
            if r.module != "robot":
                continue
            value = str(r.values[0]) if r.values else ""
            if (r.device, r.prop) == ("watchdog", "state"):
                if value == "tripped" and self.watchdog != "tripped":
                    self.rec.event(t, "watchdog_trip", "every module stopped")
                self.watchdog = value
            elif (r.device, r.prop) == ("control", "owner") and value != self.owner:
                self.rec.event(t, "control", f"control: {self.owner} -> {value}")
                self.owner = value
            elif r.prop == "state" and r.device in self.h.sup.slots:
                if self.states.get(r.device) not in (None, value):
                    self.rec.module_state(t, r.device, value, "seen in robot.get")
                self.states[r.device] = value

    def close(self) -> None:
        logging.getLogger("ramp").removeHandler(self.handler)


class RecordedClient(TestClient):
    """A harness client whose lines are recorded as the supervisor would see them."""

    def __init__(self, h: SimHarness, rec: Recorder) -> None:
        super().__init__(h)
        self.rec = rec
        host, port = self.sock.getsockname()[:2]
        self.peer = f"{host}:{port}"  # the address the server sees

    def ask(self, text: str) -> str:
        self.rec.mcp_in(self.h.clock.now(), self.peer, text)
        answer = super().ask(text)
        self.rec.mcp_out(self.h.clock.now(), self.peer, answer)
        return answer


#: (from s, until s, message sent once at the start, then heartbeats every 0.25 s)
OPERATOR = [
    (0.2, 0.2, "robot:control.acquire=(operator)"),
    (0.5, 4.5, "base:base.drive=(60,0)"),
    (4.5, 6.0, "base:base.drive=(50,20)"),
    (6.0, 6.5, "base:base.stop=()"),
    (6.5, 16.5, "ble:chain.vel=(80)"),
    # 16.5-19: silent; the watchdog trips at 17.5 and the chain stops
    (19.0, 28.0, "ble:lift.pos=(0.9)"),
    (28.0, 31.0, "base:base.drive=(-60,0)"),
    (31.0, 31.5, "robot:robot.stop=()"),
    (31.5, 31.5, "robot:control.release=()"),
]
SHELL = [(12.0, "base:lf_wheel.vel=(300)"), (12.5, "ble:chain.vel=(10)"),
         (13.0, "ble:ble.get=()")]


def run(h: SimHarness, feed: OutsideFeed, duration: float = DURATION) -> dict[str, list[str]]:
    """Drive the scenario; returns what each client sent, in order."""
    h.world.place(3.6, 1.94, 0.0)
    operator, shell = feed.client(), feed.client()
    sent: dict[str, list[str]] = {operator.peer: [], shell.peer: [], feed.monitor.peer: []}
    steps = int(round(duration / DT))
    plan = list(OPERATOR)
    last_beat = 0.0
    for k in range(steps + 1):
        t = k * DT
        if k % 2 == 0:
            feed.poll()
            sent[feed.monitor.peer].append("robot:robot.get=()base:base.get=()ble:ble.get=()")
        active = [p for p in plan if p[0] <= t + 1e-9 < max(p[1], p[0] + DT)]
        for p in active:
            if p[0] > t - DT + 1e-9:  # first step of this phase: the command itself
                operator.ask(p[2])
                sent[operator.peer].append(p[2])
                last_beat = t
        if active and t - last_beat >= 0.25 - 1e-9:
            operator.ask("")
            sent[operator.peer].append("")
            last_beat = t
        for when, text in SHELL:
            if abs(t - when) < DT / 2:
                shell.ask(text)
                sent[shell.peer].append(text)
        h.advance(DT)
    return sent


def record_sample(directory: Path, duration: float = DURATION) -> tuple[Path, dict[str, Any]]:
    """Record the scenario into `directory`; returns the file and what the test needs."""
    h = SimHarness()
    rec = Recorder(RecorderConfig(str(directory)), origin_ns=ORIGIN_NS,
                   session={"robot": "MARTE (simulated)", "config": "ramp.yaml"})
    received: dict[str, list[float]] = {}
    world_set = h.world.set_motor

    def emulator_received(name: str, duty: float) -> None:
        world_set(name, duty)
        seen = received.setdefault(name, [])
        if not seen or seen[-1] != duty:
            seen.append(duty)

    h.world.set_motor = emulator_received  # type: ignore[method-assign]
    rec.start(h.clock.now())
    feed = OutsideFeed(h, rec)
    try:
        sent = run(h, feed, duration)
    finally:
        feed.close()
        rec.close()
        h.close()
    assert rec.path is not None
    return rec.path, {"sent": sent, "emulator": received, "dropped": rec.dropped}


if __name__ == "__main__":
    path, _ = record_sample(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
    print(path)
