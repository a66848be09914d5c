"""`ramp sim mission --realtime`: the robot and the arena in a process of their own, the
autonomy in the command's process, as on the robot (`ramp.simulation.arena_process`).

- The backend serves MCP from the child (the listening socket is the child's, not the
  parent's), the autonomy acquires control, localizes and goes on; an operator takes control
  over MCP and the mission pauses; SIGTERM of the parent stops the robot, ends the child and
  frees the port.
- The `sim` module, served by the child's backend, still reaches the child's emulators:
  `sim:lidar.blind=(1)` blinds the Hokuyo and `sim:imu.shift=(DEG)` tilts the IMU's samples
  as they arrive over the sensor link.
- A child that is killed ends the run as `error`, saying so; a parent that is killed leaves
  no child behind.

Functional, not timing: `python -m bench --only realtime` measures the tick.
"""

from __future__ import annotations

import math
import os
import re
import select
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from ramp.autonomy.config import ImuConfig
from ramp.autonomy.hal.hokuyo import HokuyoLidar
from ramp.autonomy.hal.simlink import SimLinkImu
from ramp.clock import MonotonicClock
from ramp.scheduler import Scheduler
from ramp.simulation.arena_process import ArenaProcess
from ramp.simulation.mission import MissionOptions
from tests.harness import REPO, ask_line

pytestmark = pytest.mark.timeout(120)
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


class Mission:
    """`ramp sim mission --realtime --port 0 ARGS` as a process, its stdout read by line."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "ramp.cli", "sim", "mission", "--realtime", "--port", "0",
             *args], cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            env=ENV)
        self.lines: list[str] = []
        m = self.expect(r"MCP on ([\d.]+):(\d+)", 60)
        self.host, self.port = m.group(1), int(m.group(2))
        m = self.expect(r"the robot and the arena run in process (\d+), the autonomy in "
                        r"process (\d+)", 5)
        self.child, self.parent = int(m.group(1)), int(m.group(2))

    def expect(self, pattern: str, timeout: float) -> re.Match[str]:
        assert self.proc.stdout is not None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            r, _, _ = select.select([self.proc.stdout], [], [], 0.2)
            if r:
                line = self.proc.stdout.readline()
                if not line:
                    break
                self.lines.append(line)
                m = re.search(pattern, line)
                if m:
                    return m
        raise AssertionError(f"no line matching {pattern!r} in {timeout} s:\n"
                             + "".join(self.lines))

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


@pytest.fixture
def cleanup() -> Iterator[list[Mission]]:
    started: list[Mission] = []
    yield started
    for m in started:
        m.close()
        with_gone(m.child)


def with_gone(pid: int) -> None:
    """Kill `pid` if a failed test left it running (it is ours: a child of our mission)."""
    if running(pid):
        os.kill(pid, signal.SIGKILL)


def running(pid: int) -> bool:
    """`pid` exists and is not a zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def parent_of(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def listener_inode(port: int) -> int:
    """The inode of the socket listening on TCP `port` (from /proc/net/tcp)."""
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        f = line.split()
        if int(f[1].split(":")[1], 16) == port and f[3] == "0A":
            return int(f[9])
    raise AssertionError(f"nothing listens on port {port}")


def holds_socket(pid: int, inode: int) -> bool:
    fd_dir = Path(f"/proc/{pid}/fd")
    for fd in fd_dir.iterdir():
        try:
            if os.readlink(fd) == f"socket:[{inode}]":
                return True
        except OSError:
            continue
    return False


def wait_for(predicate: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.1)
    return predicate()


def test_the_backend_runs_in_its_own_process_and_the_operator_can_take_over(
        cleanup: list[Mission]) -> None:
    m = Mission("--duration", "120")
    cleanup.append(m)
    assert m.parent == m.proc.pid and m.child != m.parent
    assert parent_of(m.child) == m.parent
    inode = listener_inode(m.port)
    assert holds_socket(m.child, inode) and not holds_socket(m.parent, inode)
    # The autonomy, in the parent, localizes against the child's sensors and goes on.
    m.expect(r"initial_localization -> prepare_for_scan", 60)
    sock = socket.create_connection((m.host, m.port), timeout=5)
    try:
        assert "robot:control.owner=(autonomy)" in ask_line(sock, "robot:robot.get=()")
        assert ask_line(sock, "robot:control.acquire=(operator)") == ""
        m.expect(r"-> paused", 10)
        assert ask_line(sock, "robot:control.release=()") == ""
        m.expect(r"paused -> acquire_control", 10)
    finally:
        sock.close()
    m.proc.send_signal(signal.SIGTERM)
    out, _err = m.proc.communicate(timeout=30)
    assert '"outcome": "error"' not in out or "interrupted" in out
    assert "error         interrupted" in out
    assert wait_for(lambda: not running(m.child), 10), "the simulator's process outlived us"
    with pytest.raises(OSError):
        socket.create_connection((m.host, m.port), timeout=2).close()


def test_a_killed_simulator_ends_the_run_as_an_error_saying_so(cleanup: list[Mission]) -> None:
    m = Mission("--duration", "120", "--json")
    cleanup.append(m)
    m.expect(r"acquire_control -> initial_localization", 60)
    os.kill(m.child, signal.SIGKILL)
    out, err = m.proc.communicate(timeout=30)
    assert m.proc.returncode == 1
    summary = out.strip().splitlines()[-1]
    assert '"outcome": "error"' in summary
    assert f"the simulator's process (pid {m.child}) is gone (killed by SIGKILL)" in summary
    assert "is gone" in err


def test_a_killed_parent_leaves_no_simulator_behind(cleanup: list[Mission]) -> None:
    m = Mission("--duration", "120")
    cleanup.append(m)
    os.kill(m.parent, signal.SIGKILL)
    m.proc.communicate(timeout=10)
    assert wait_for(lambda: not running(m.child), 15), "the simulator's process outlived us"
    with pytest.raises(OSError):
        socket.create_connection((m.host, m.port), timeout=2).close()


def test_the_sim_module_reaches_the_emulators_in_the_simulators_process() -> None:
    arena = ArenaProcess(MissionOptions(realtime=True, port=0, duration=60.0))
    clock = MonotonicClock()
    sched = Scheduler(clock, 100.0)
    lidar = HokuyoLidar(arena.lidar_url, clock=clock, loop=sched)
    imu = SimLinkImu(ImuConfig(driver="simlink", data_interval_ms=8), link=arena.link)
    mcp = socket.create_connection(arena.mcp_address, timeout=5)
    try:
        arena.attach(sched)
        sched.add_task("lidar", 100.0, lidar.tick)
        sched.add_task("imu", 100.0, imu.tick)
        imu.open(clock.now())
        lidar.start()
        lidar.start_stream()

        def run_until(done: Callable[[], bool], seconds: float) -> bool:
            end = clock.now() + seconds
            sched.run(lambda: done() or clock.now() >= end)
            return done()

        def gravity() -> tuple[float, float, float]:
            imu.drain()
            run_until(lambda: False, 0.3)
            s = imu.drain()
            n = len(s)
            assert n > 10, "no IMU samples over the sensor link"
            g = [sum(x.specific_force_g[i] for x in s) / n for i in range(3)]
            return (g[0], g[1], g[2])

        assert run_until(lambda: lidar.scans_received >= 3 and imu.ready(), 20)
        scan = lidar.latest
        assert scan is not None and int(scan.valid.sum()) > 500
        before = gravity()
        assert ask_line(mcp, "sim:lidar.blind=(1)") == ""
        seen = lidar.scans_received
        assert run_until(lambda: lidar.scans_received >= seen + 3, 5)
        scan = lidar.latest
        assert scan is not None and not scan.valid.any()
        assert ask_line(mcp, "sim:imu.shift=(20)") == ""
        run_until(lambda: False, 0.5)  # the mount turns in 0.2 s
        after = gravity()
        dot = sum(a * b for a, b in zip(before, after, strict=True))
        norm = math.dist(before, (0, 0, 0)) * math.dist(after, (0, 0, 0))
        assert math.degrees(math.acos(min(1.0, dot / norm))) == pytest.approx(20.0, abs=1.0)
    finally:
        mcp.close()
        lidar.stop()
        imu.close()
        end = arena.finish()
    assert end is not None and end["why"] == "the autonomy's process asked"
    assert arena.proc.returncode == 0


def test_a_port_in_use_ends_the_command_saying_so() -> None:
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    try:
        out = subprocess.run(
            [sys.executable, "-m", "ramp.cli", "sim", "mission", "--realtime", "--port",
             str(busy.getsockname()[1]), "--duration", "5"], cwd=REPO, capture_output=True,
            text=True, timeout=90, env=ENV)
    finally:
        busy.close()
    assert out.returncode == 1
    assert ("ramp sim mission: the simulator's process could not start: OSError: [Errno 98] "
            "Address already in use") in out.stderr
