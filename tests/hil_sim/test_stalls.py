"""Stalls and freezes (SPEC 2.2): after a gap longer than `scheduler.stall_limit` every module
stops before anything else reaches a wire, the event is logged once with the gap's length,
the watchdog reads `tripped`, and motion resumes only on a new motion request.

On the virtual clock a freeze is a jump of the clock; against a real `ramp run` it is SIGSTOP
and SIGCONT, with the base's Sabertooth bus real (`sim: false`) on a pty emulator in this
process, so what goes out after the freeze is read from the wire itself.
"""

from __future__ import annotations

import logging
import re
import signal
import socket
import time
from pathlib import Path

import pytest

from firmware_like.pty_link import PtyLink
from firmware_like.sabertooth import SabertoothEmulator, SabertoothPtyDevice
from tests.harness import MARTE_YAML, SimHarness
from tests.harness import ask_line as ask
from tests.harness import start_ramp as start

MOTOR_COMMANDS = (0, 1, 4, 5)  # forward/backward for motor 1 and 2: the data byte is the speed


def motion_after(packets: list[tuple[float, int, int, int]], start: int) -> list[tuple]:
    """Motor packets from index `start` on that command a non-zero speed."""
    return [p for p in packets[start:] if p[2] in MOTOR_COMMANDS and p[3] != 0]


def health(line: str) -> dict[str, str]:
    return {f"{d}.{p}": v for d, p, v in re.findall(r"robot:(\w+)\.(\w+)=\(([^)]*)\)", line)}


@pytest.fixture
def h() -> SimHarness:
    harness = SimHarness()
    yield harness
    harness.close()


def test_a_clock_jump_stops_every_module_before_any_refresh_reaches_the_wire(
        h: SimHarness, caplog: pytest.LogCaptureFixture) -> None:
    c = h.connect()
    emu = h.backplane.sabertooth["base_motors"].emulator
    assert c.ask("base:base.drive=(50,0)") == ""
    for _ in range(5):
        h.advance(0.1)
        assert c.ask("") == ""
    assert emu.duty(128, 1) > 0.3
    device = h.backplane.sabertooth["base_motors"]
    with caplog.at_level(logging.ERROR, logger="ramp.stall"):
        device.service(h.clock.now())  # what went out before the freeze ...
        h.clock.advance(0.6)  # ... the process did not run for 0.6 s (< the 1 s watchdog) ...
        device.service(h.clock.now())  # ... the wire did
        assert emu.timed_out(128)  # the controllers' own timeout stopped the wheels
        mark = len(emu.packets)
        h.advance(0.3)
        assert c.ask("") == ""
        h.advance(0.3)
    assert motion_after(list(emu.packets), mark) == []
    assert all(emu.duty(a, m) == 0.0 for a in (128, 129) for m in (1, 2))
    rows = health(c.ask("robot:robot.get=()"))
    assert rows["watchdog.state"] == "tripped"
    assert "base:lf_wheel.vel=(0)" in c.ask("base:base.get=()")
    stalls = [r.getMessage() for r in caplog.records if "stalled" in r.getMessage()]
    assert len(stalls) == 1, stalls
    assert re.search(r"stalled for (6\d\d) ms", stalls[0]), stalls[0]
    # heartbeats do not restart anything; a new motion request does
    h.advance(0.2)
    assert motion_after(list(emu.packets), mark) == []
    assert c.ask("base:base.drive=(30,0)") == ""
    h.advance(0.05)
    assert emu.duty(128, 1) > 0.2
    assert health(c.ask("robot:robot.get=()"))["watchdog.state"] == "armed"


def test_motion_computed_before_a_gap_inside_a_task_is_dropped(h: SimHarness) -> None:
    """The gap falls in the middle of a task that then commands a motor: that stale value
    never reaches the wire, and the stop comes before the next unit of work."""
    device = h.backplane.sabertooth["base_motors"]
    emu = device.emulator
    wheel = h.sup.slots["base"].module
    state = {"armed": False, "mark": 0}
    motor = h.sup.buses["base_motors"].motors[0]

    def frozen_mid_task(now: float, dt: float) -> None:
        if state["armed"]:
            state["armed"] = False
            device.service(now)  # what went out before the freeze ...
            h.clock.advance(0.7)  # ... frozen here ...
            device.service(h.clock.now())  # ... and the wire delivered it meanwhile
            state["mark"] = len(emu.packets)
            motor.set_duty(0.8)  # computed before the freeze

    h.sup.scheduler.add_task("frozen_mid_task", 100, frozen_mid_task)
    c = h.connect()
    assert c.ask("base:base.drive=(40,0)") == ""
    h.advance(0.2)
    state["armed"] = True
    h.advance(0.1)  # the frozen tick (the clock is now 0.7 s further on) ...
    h.advance(0.3)  # ... and the loop going on after it
    assert state["mark"] > 0
    assert motion_after(list(emu.packets), state["mark"]) == []
    assert all(emu.duty(a, m) == 0.0 for a in (128, 129) for m in (1, 2))
    assert not wheel.is_moving()
    assert h.sup.watchdog.state == "tripped"


def test_a_quiet_gap_shorter_than_the_limit_changes_nothing(h: SimHarness) -> None:
    c = h.connect()
    assert c.ask("base:base.drive=(50,0)") == ""
    h.advance(0.1)
    h.clock.advance(0.2)  # under the 0.25 s stall_limit
    h.advance(0.1)
    assert c.ask("") == ""
    assert health(c.ask("robot:robot.get=()"))["watchdog.state"] == "armed"
    assert h.sup.scheduler.stalls == 0


@pytest.mark.timeout(60)
@pytest.mark.parametrize("freeze_s", [0.6, 2.0])
def test_sigstop_sigcont_sends_nothing_but_zeros_after_the_freeze(
        tmp_path: Path, freeze_s: float) -> None:
    """Drive at 50 % with heartbeats every 0.1 s, freeze the process with SIGSTOP (the
    controllers' own 0.5 s timeout stops the wheels meanwhile), then SIGCONT: not one
    non-zero motor packet may follow, whether the freeze is shorter or longer than the
    watchdog; the stall is logged once and the watchdog reads `tripped`."""
    link = PtyLink("base_motors", tmp_path)
    emu = SabertoothEmulator((128, 129))
    device = SabertoothPtyDevice(link, emu)
    text = MARTE_YAML.replace(
        "base_motors: {driver: sabertooth, port: /dev/ttyUSB0, baud: 9600, timeout: 0.5}",
        f"base_motors: {{driver: sabertooth, port: {link.path}, baud: 9600, timeout: 0.5,"
        " sim: false}")
    assert text != MARTE_YAML
    cfg = tmp_path / "bench.yaml"
    cfg.write_text(text)
    log_path = tmp_path / "ramp.log"
    with log_path.open("w") as log_file:
        proc, host, port = start(["--sim", "--config", str(cfg), "--host", "127.0.0.1",
                                  "--port", "0"], env={"TMPDIR": str(tmp_path)},
                                 stderr=log_file)

    beats = [0]

    def run_for(seconds: float, s: socket.socket) -> None:
        """Heartbeats every 0.1 s (sent even while the process is stopped) and the wire."""
        end = time.monotonic() + seconds
        next_beat = time.monotonic()
        while time.monotonic() < end:
            if time.monotonic() >= next_beat:
                s.sendall(b"\n")
                beats[0] += 1
                next_beat += 0.1
            device.service(time.monotonic())
            time.sleep(0.005)

    try:
        with socket.create_connection((host, port), timeout=10) as s:
            assert ask(s, "base:base.drive=(50,0)") == ""
            s.settimeout(None)
            run_for(0.5, s)
            assert emu.duty(128, 1) == pytest.approx(round(0.5 * 127) / 127, abs=1e-6)
            proc.send_signal(signal.SIGSTOP)
            run_for(0.05, s)  # whatever was already written arrives
            mark = len(emu.packets)
            run_for(freeze_s, s)
            assert emu.timed_out(128) and emu.timed_out(129)  # their own timeout fired
            proc.send_signal(signal.SIGCONT)
            run_for(0.6, s)
            assert motion_after(list(emu.packets), mark) == []
            assert all(emu.duty(a, m) == 0.0 for a in (128, 129) for m in (1, 2))
            assert len(emu.packets) > mark  # zeros (and refreshes of zeros) went out
            s.settimeout(10)
            s.sendall(b"robot:robot.get=()\n")
            buf = b""
            while buf.count(b"\n") < beats[0] + 1:  # every heartbeat's answer, then the get's
                buf += s.recv(65536)
            lines = buf.decode().split("\n")
            assert lines[:beats[0]] == [""] * beats[0]
            assert health(lines[beats[0]])["watchdog.state"] == "tripped"
            assert ask(s, "base:base.drive=(30,0)") == ""  # a new request moves again
            run_for(0.2, s)
            assert emu.duty(128, 1) > 0.2
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGCONT)
            proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=10)
        link.close()
    log = log_path.read_text()
    stalls = [line for line in log.splitlines() if "stalled" in line]
    assert len(stalls) == 1, log
    gap_ms = int(re.search(r"stalled for (\d+) ms", stalls[0]).group(1))  # type: ignore[union-attr]
    assert gap_ms >= freeze_s * 1000 - 50, stalls[0]


def test_a_task_stuck_for_300_ms_shows_in_tick_late(h: SimHarness) -> None:
    """The ticks it swallowed are skipped, but how late the loop was is not hidden: the max
    of `tick.late` used to stay at the lateness of the tick that came after."""
    state = {"armed": False}

    def stuck(now: float, dt: float) -> None:
        if state["armed"]:
            state["armed"] = False
            h.clock.advance(0.3)

    h.sup.scheduler.add_task("stuck", 100, stuck)
    c = h.connect()
    h.advance(0.1)
    state["armed"] = True
    h.advance(0.5)
    _, _, worst = (int(x) for x in health(c.ask("robot:robot.get=()"))["tick.late"].split(","))
    assert worst >= 290_000
