"""A short simulated MARTE run recorded by the supervisor itself: the tests' and the
README's sample.

    .venv/bin/python -m tests.hil_sim.recorder_sample DIR         # virtual clock, ~2 s
    .venv/bin/python -m tests.hil_sim.recorder_sample --live DIR  # ramp run --sim --record, 41 s

Either prints the MCAP file's path. The first builds the supervisor (the MARTE config on the
physics model, wire-level Sabertooth emulators: `tests.harness.SimHarness`) with a
`Recorder` exactly as `ramp run --record DIR` does (`ramp.runtime.build(..., recorder=...)`)
on a virtual clock, so the file is the same every run; the second plays the same scenario
over MCP against a real `ramp run --sim --record DIR` process on the wall clock (the
README's picture, with real tick lateness). Either way the supervisor records the MCP lines
of every client, `robot.get` and each module's get at 10 Hz, every command handed to a
driver, module state changes, watchdog and control events, and its log at WARNING and above.

The run (41 s): an operator takes control, drives MARTE out of the start box across the
empty arena into the digging region, turns a little, digs with the chain, then goes silent,
so the watchdog trips; comes back, raises the bin, backs out and gives control up. A shell
client meanwhile sends a bad request and is refused a command while the operator owns
control; a console polls `robot.get` at 2 Hz.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from firmware_like.marte import MOTORS
from ramp.recorder import Recorder, RecorderConfig
from ramp.recorder.writer import recording_files
from tests.harness import REPO, SimHarness, ask_line

ORIGIN_NS = 1_779_285_600_000_000_000  # 2026-05-20 14:00:00 UTC, a made-up run date
DT = 0.05                              # s per step of the scenario
DURATION = 41.0

#: (from s, until s, message sent once at the start, then heartbeats every 0.25 s)
OPERATOR = [
    (0.2, 0.2, "robot:control.acquire=(operator)"),
    (0.5, 11.5, "base:base.drive=(100,0)"),   # out of the start box, across the obstacle area
    (11.5, 13.0, "base:base.drive=(50,20)"),
    (13.0, 13.5, "base:base.stop=()"),
    (13.5, 23.5, "ble:chain.vel=(80)"),       # dig
    # 23.5-26: silent; the watchdog trips 1 s after the last heartbeat and the chain stops
    (26.0, 35.0, "ble:lift.pos=(0.9)"),       # raise the bin
    (35.0, 40.0, "base:base.drive=(-60,0)"),  # back out
    (40.0, 40.5, "robot:robot.stop=()"),
    (40.5, 40.5, "robot:control.release=()"),
]
SHELL = [(18.0, "base:lf_wheel.vel=(300)"), (18.5, "ble:chain.vel=(10)"),
         (19.0, "ble:ble.get=()")]
CONSOLE = "robot:robot.get=()"  # polled at 2 Hz


def script(duration: float = DURATION) -> list[tuple[float, str, str]]:
    """The scenario as (time s, client, message), in order; the clients are `operator`,
    `shell` and `console`."""
    out: list[tuple[float, str, str]] = []
    last_beat = 0.0
    for k in range(int(round(duration / DT)) + 1):
        t = round(k * DT, 6)
        if k % 10 == 0:
            out.append((t, "console", CONSOLE))
        active = [p for p in OPERATOR if p[0] <= t + 1e-9 < max(p[1], p[0] + DT)]
        for p in active:
            if p[0] > t - DT + 1e-9:  # first step of this phase: the command itself
                out.append((t, "operator", p[2]))
                last_beat = t
        if active and t - last_beat >= 0.25 - 1e-9:
            out.append((t, "operator", ""))
            last_beat = t
        out.extend((t, "shell", text) for when, text in SHELL if abs(t - when) < DT / 2)
    return out


def peer(sock: socket.socket) -> str:
    """A client's address as the server sees it (and records it)."""
    host, port = sock.getsockname()[:2]
    return f"{host}:{port}"


def run(h: SimHarness, duration: float = DURATION) -> dict[str, list[str]]:
    """Play the scenario on the harness's virtual clock; returns what each client sent (by
    its address), in order."""
    clients = {name: h.connect() for name in ("operator", "shell", "console")}
    sent: dict[str, list[str]] = {peer(c.sock): [] for c in clients.values()}
    events = script(duration)
    i = 0
    for k in range(int(round(duration / DT)) + 1):
        t = round(k * DT, 6)
        while i < len(events) and events[i][0] <= t:
            _, name, text = events[i]
            clients[name].ask(text)
            sent[peer(clients[name].sock)].append(text)
            i += 1
        h.advance(DT)
    return sent


def live(directory: Path, duration: float = DURATION) -> Path:
    """The same scenario against a real `ramp run --sim --record DIRECTORY` process on the
    wall clock (the README's picture: real tick lateness); returns the file."""
    proc = subprocess.Popen([sys.executable, "-m", "ramp.cli", "run", "--sim", "--host",
                             "127.0.0.1", "--port", "0", "--record", str(directory),
                             "--log-level", "warning"], cwd=REPO, stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout is not None
        port = int(proc.stdout.readline().rsplit(":", 1)[1])
        socks = {name: socket.create_connection(("127.0.0.1", port))
                 for name in ("operator", "shell", "console")}
        start = time.monotonic()
        for t, name, text in script(duration):
            delay = start + t - time.monotonic()
            if delay > 0:
                time.sleep(delay)  # a test program: the scenario's own clock
            ask_line(socks[name], text)
        for sock in socks.values():
            sock.close()
        proc.send_signal(signal.SIGTERM)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    files = recording_files(directory)
    return files[-1][1]


def record_sample(directory: Path, duration: float = DURATION) -> tuple[Path, dict[str, Any]]:
    """Record the scenario into `directory`; returns the file and what the test needs:
    what each client sent, what the Sabertooth emulators applied (each change of each
    motor), and the records dropped."""
    rec = Recorder(RecorderConfig(str(directory)), origin_ns=ORIGIN_NS,
                   session={"config": "ramp.yaml", "mode": "simulated (virtual clock)"})
    h = SimHarness(recorder=rec)  # the robot where `ramp run --sim` puts it: the start box
    received: dict[str, list[float]] = {}
    world = h.world

    def emulator_received(now: float, dt: float) -> None:
        # What the emulators applied, read from the world after every tick (its class may be
        # compiled, so its `set_motor` cannot be wrapped on the instance).
        for name in MOTORS:
            duty = world.duty(name)
            seen = received.setdefault(name, [])
            if not seen or seen[-1] != duty:
                seen.append(duty)

    h.sup.scheduler.add_task("test.emulator_received", h.sup.scheduler.rate_hz,
                             emulator_received)
    try:
        sent = run(h, duration)
    finally:
        h.close()  # the supervisor closes the recorder once the motors are stopped
    assert rec.path is not None
    return rec.path, {"sent": sent, "emulator": received, "dropped": rec.dropped}


if __name__ == "__main__":
    if sys.argv[1:2] == ["--live"]:
        print(live(Path(sys.argv[2] if len(sys.argv) > 2 else ".")))
    else:
        path, _ = record_sample(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
        print(path)
