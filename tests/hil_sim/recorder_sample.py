"""A short simulated MARTE run, recorded by the supervisor itself: the README's sample.

    .venv/bin/python -m tests.hil_sim.recorder_sample DIR    # prints the MCAP file's path

The supervisor (the MARTE config on the physics model, wire-level Sabertooth emulators, a
virtual clock: `tests.harness.SimHarness`) is built with a `Recorder`, exactly as `ramp run
--record DIR` builds it (`ramp.runtime.build(..., recorder=...)`): it records the MCP lines
of every client, `robot.get` and each module's get at 10 Hz, every command handed to a
driver, module state changes, watchdog and control events, and its log at WARNING and above.
On a virtual clock the run is the same every time and takes a few seconds.

The run (32 s): an operator takes control, drives MARTE into the digging region, turns a
little, digs with the chain, then goes silent, so the watchdog trips; comes back, raises the
bin, backs out and gives control up. A shell client meanwhile sends a bad request and is
refused a command while the operator owns control; a console polls `robot.get` at 2 Hz.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from ramp.recorder import Recorder, RecorderConfig
from tests.harness import SimHarness, TestClient

ORIGIN_NS = 1_779_285_600_000_000_000  # 2026-05-20 14:00:00 UTC, a made-up run date
DT = 0.05                              # s of simulated time per step
DURATION = 32.0


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
CONSOLE = "robot:robot.get=()"


def peer(c: TestClient) -> str:
    """The client's address as the server sees it (and records it)."""
    host, port = c.sock.getsockname()[:2]
    return f"{host}:{port}"


def run(h: SimHarness, duration: float = DURATION) -> dict[str, list[str]]:
    """Drive the scenario; returns what each client sent (by its address), in order."""
    h.world.place(3.6, 1.94, 0.0)
    operator, shell, console = h.connect(), h.connect(), h.connect()
    sent: dict[str, list[str]] = {peer(operator): [], peer(shell): [], peer(console): []}
    steps = int(round(duration / DT))
    last_beat = 0.0
    for k in range(steps + 1):
        t = k * DT
        if k % 10 == 0:
            console.ask(CONSOLE)
            sent[peer(console)].append(CONSOLE)
        active = [p for p in OPERATOR if p[0] <= t + 1e-9 < max(p[1], p[0] + DT)]
        for p in active:
            if p[0] > t - DT + 1e-9:  # first step of this phase: the command itself
                operator.ask(p[2])
                sent[peer(operator)].append(p[2])
                last_beat = t
        if active and t - last_beat >= 0.25 - 1e-9:
            operator.ask("")
            sent[peer(operator)].append("")
            last_beat = t
        for when, text in SHELL:
            if abs(t - when) < DT / 2:
                shell.ask(text)
                sent[peer(shell)].append(text)
        h.advance(DT)
    return sent


def record_sample(directory: Path, duration: float = DURATION) -> tuple[Path, dict[str, Any]]:
    """Record the scenario into `directory`; returns the file and what the test needs:
    what each client sent, what the Sabertooth emulators applied (each change of each
    motor), and the records dropped."""
    rec = Recorder(RecorderConfig(str(directory)), origin_ns=ORIGIN_NS,
                   session={"config": "ramp.yaml", "mode": "simulated (virtual clock)"})
    h = SimHarness(recorder=rec)
    received: dict[str, list[float]] = {}
    world_set = h.world.set_motor

    def emulator_received(name: str, duty: float) -> None:
        world_set(name, duty)
        seen = received.setdefault(name, [])
        if not seen or seen[-1] != duty:
            seen.append(duty)

    h.world.set_motor = emulator_received  # type: ignore[method-assign]
    try:
        sent = run(h, duration)
    finally:
        h.close()  # the supervisor closes the recorder once the motors are stopped
    assert rec.path is not None
    return rec.path, {"sent": sent, "emulator": received, "dropped": rec.dropped}


if __name__ == "__main__":
    path, _ = record_sample(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
    print(path)
