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

import contextlib
import json
import math
import os
import re
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NoReturn

import pytest

from ramp.autonomy.config import ImuConfig
from ramp.autonomy.hal.hokuyo import HokuyoLidar
from ramp.autonomy.hal.simlink import SensorLink, SimLinkImu
from ramp.clock import MonotonicClock
from ramp.scheduler import Scheduler
from ramp.simulation.arena_process import Arena, ArenaProcess
from ramp.simulation.mission import MissionOptions, MissionRun
from tests.harness import REPO, ask_line

# Each test's waits, summed, fit in its timeout (a loaded 2-core machine: the child's start
# alone has taken 20 s); the first test's add up to 195 s.
pytestmark = pytest.mark.timeout(120)
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


class Mission:
    """`ramp sim mission --realtime --port 0 ARGS` as a process, its stdout read by line;
    on `started` (the test's cleanup) before anything can fail."""

    def __init__(self, started: list[Mission], *args: str) -> None:
        self.child = self.backend = 0
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "ramp.cli", "sim", "mission", "--realtime", "--port", "0",
             *args], cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            env=ENV)
        started.append(self)
        self.lines: list[str] = []
        m = self.expect(r"MCP on ([\d.]+):(\d+)", 60)
        self.host, self.port = m.group(1), int(m.group(2))
        m = self.expect(r"the backend runs in process (\d+) as `ramp run` runs \(([^;]*); "
                        r"stall guard (\w+)\), the simulated hardware and the arena in process "
                        r"(\d+), the autonomy in process (\d+)", 5)
        self.backend, self.policy, self.guard = int(m.group(1)), m.group(2), m.group(3)
        self.child, self.parent = int(m.group(4)), int(m.group(5))

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
        for pid in (m.child, m.backend):
            if pid:
                with_gone(pid)


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


@pytest.mark.timeout(240)
def test_the_backend_runs_in_its_own_process_and_the_operator_can_take_over(
        cleanup: list[Mission]) -> None:
    m = Mission(cleanup, "--duration", "120", "--json")
    assert m.parent == m.proc.pid and len({m.child, m.parent, m.backend}) == 3
    assert parent_of(m.child) == m.parent and parent_of(m.backend) == m.child
    # The backend serves MCP from its own process, run as `ramp run` runs: the stall
    # guard's thread watches its loop.
    inode = listener_inode(m.port)
    assert holds_socket(m.backend, inode)
    assert not holds_socket(m.child, inode) and not holds_socket(m.parent, inode)
    assert m.guard == "on"
    # (Python 3.11 does not name its threads for the OS: the guard is the second thread.)
    assert len(list(Path(f"/proc/{m.backend}/task").iterdir())) >= 2
    # The autonomy, in the parent, localizes against the child's sensors and goes on.
    m.expect(r"initial_localization -> prepare_for_scan", 60)
    sock = socket.create_connection((m.host, m.port), timeout=5)
    try:
        assert "robot:control.owner=(autonomy)" in ask_line(sock, "robot:robot.get=()")
        assert ask_line(sock, "robot:control.acquire=(operator)") == ""
        m.expect(r"-> paused", 10)
        assert ask_line(sock, "robot:control.release=()") == ""
        m.expect(r"paused -> acquire_control", 10)
        # The operator drives, and the command is ended with the wheels turning: the child's
        # shutdown must stop them (the autonomy, without control, sends no stop).
        assert ask_line(sock, "robot:control.acquire=(operator)") == ""
        assert ask_line(sock, "base:base.drive=(50,0)") == ""
        m.proc.send_signal(signal.SIGTERM)
        out, _err = m.proc.communicate(timeout=30)
    finally:
        sock.close()
    assert "error         interrupted" in out
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["outcome"] == "error" and summary["error"] == "interrupted"
    motors = summary["motors_at_end"]
    assert motors and set(motors.values()) == {0.0}, motors
    service = summary["backend_service"]
    assert service["stall_guard"] and service["gc_frozen"] > 0, service
    assert summary["processes"]["backend"] == summary["backend_tick"]["pid"] == m.backend
    assert wait_for(lambda: not running(m.child), 10), "the simulator's process outlived us"
    assert wait_for(lambda: not running(m.backend), 10), "the backend's process outlived us"
    with pytest.raises(OSError):
        socket.create_connection((m.host, m.port), timeout=2).close()


def test_a_killed_simulator_ends_the_run_as_an_error_saying_so(cleanup: list[Mission]) -> None:
    m = Mission(cleanup, "--duration", "120", "--json")
    m.expect(r"acquire_control -> initial_localization", 60)
    os.kill(m.child, signal.SIGKILL)
    out, err = m.proc.communicate(timeout=30)
    assert m.proc.returncode == 1
    summary = out.strip().splitlines()[-1]
    assert '"outcome": "error"' in summary
    assert f"the simulator's process (pid {m.child}) is gone (killed by SIGKILL)" in summary
    assert "is gone" in err
    assert wait_for(lambda: not running(m.backend), 15), "the backend's process outlived us"


def test_a_killed_parent_leaves_no_simulator_behind(cleanup: list[Mission]) -> None:
    m = Mission(cleanup, "--duration", "120")
    os.kill(m.parent, signal.SIGKILL)
    m.proc.communicate(timeout=10)
    assert wait_for(lambda: not running(m.child), 15), "the simulator's process outlived us"
    assert wait_for(lambda: not running(m.backend), 15), "the backend's process outlived us"
    with pytest.raises(OSError):
        socket.create_connection((m.host, m.port), timeout=2).close()


def test_the_sim_module_reaches_the_emulators_in_the_simulators_process() -> None:
    arena = ArenaProcess(MissionOptions(realtime=True, port=0, duration=60.0))
    with contextlib.ExitStack() as cleanup:
        cleanup.callback(arena.finish)  # first: whatever fails next, the child ends
        clock = MonotonicClock()
        sched = Scheduler(clock, 100.0)
        lidar = HokuyoLidar(arena.lidar_url, clock=clock, loop=sched)
        cleanup.callback(lidar.stop)
        imu = SimLinkImu(ImuConfig(driver="simlink", data_interval_ms=8), link=arena.link)
        cleanup.callback(imu.close)
        mcp = socket.create_connection(arena.mcp_address, timeout=5)
        cleanup.callback(mcp.close)
        sim_module_reaches_the_emulators(arena, clock, sched, lidar, imu, mcp)
    end = arena.finish()
    assert end is not None and end["why"] == "the autonomy's process asked"
    assert arena.proc.returncode == 0


def sim_module_reaches_the_emulators(arena: ArenaProcess, clock: MonotonicClock,
                                     sched: Scheduler, lidar: HokuyoLidar, imu: SimLinkImu,
                                     mcp: socket.socket) -> None:
    """The `sim` module, served by the child's backend, reaches its emulators."""
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
    assert re.search(r"ramp sim mission: the simulator's process \(pid \d+\) could not "
                     r"start: the backend's process \(pid \d+\) could not start: "
                     r"OSError: \[Errno 98\] Address already in use", out.stderr)


# -- ends that go wrong: nothing is left running, every motor stops -----------------------------
def broken(*args: object, **kwargs: object) -> NoReturn:
    raise RuntimeError("broken on purpose")


def test_a_child_that_fails_to_build_stops_and_closes_what_it_built(
        monkeypatch: pytest.MonkeyPatch) -> None:
    built: list[Arena] = []
    wait = Arena._wait_backend

    def served_then_broken(self: Arena, timeout_s: float) -> NoReturn:
        wait(self, timeout_s)  # the backend's process serves, then a later step fails
        built.append(self)
        broken()

    monkeypatch.setattr(Arena, "_wait_backend", served_then_broken)
    a, b = socket.socketpair()
    link = SensorLink(a)
    try:
        with pytest.raises(RuntimeError, match="broken on purpose"):
            Arena(MissionOptions(realtime=True, port=0), link)
    finally:
        link.close()
        b.close()
    (arena,) = built
    assert arena.backend_proc.returncode == 0  # told to stop: it stopped every motor
    assert arena.backend_end is not None
    assert arena.sensors.closed and arena.hw.closed
    with pytest.raises(OSError):
        socket.create_connection(arena.mcp_address, timeout=2).close()


def test_the_child_stops_every_motor_before_its_end_and_closes_all_if_a_step_fails(
        monkeypatch: pytest.MonkeyPatch) -> None:
    a, b = socket.socketpair()
    arena = Arena(MissionOptions(realtime=True, port=0), SensorLink(a))
    peer = SensorLink(b)
    ends: list[dict[str, Any]] = []
    peer.on("end", ends.append)
    sensors_close = arena.sensors.close
    mcp = socket.create_connection(arena.mcp_address, timeout=5)
    try:
        said: list[str] = []
        operator = threading.Thread(target=lambda: said.extend(
            ask_line(mcp, line) for line in ("robot:control.acquire=(operator)",
                                             "base:base.drive=(50,0)")))
        operator.start()
        arena.scheduler.run_for(1.0)  # the hardware; the backend runs in its own process
        operator.join(5)
        assert said == ["", ""] and arena.world.duty("base.lf_wheel") > 0.3  # driving
        events: list[str] = []
        end_backend, send = arena._end_backend, arena.link.send
        monkeypatch.setattr(arena, "_end_backend",
                            lambda: (events.append("backend stopped"), end_backend())[1])
        monkeypatch.setattr(arena.link, "send",
                            lambda kind, **f: (events.append(kind), send(kind, **f))[1])
        monkeypatch.setattr(arena.sensors, "close", broken)
        arena.stop("the test")
        with pytest.raises(RuntimeError, match="broken on purpose"):
            arena.run()
        assert events.index("backend stopped") < events.index("end")
        assert arena.backend_proc.returncode == 0 and arena.backend_end is not None
        assert arena.link.closed  # after the step that failed
        for _ in range(10):
            peer.pump(0.1)
        (end,) = ends
        assert end["why"] == "the test" and set(end["motors"].values()) == {0.0}
        assert end["backend"]["pid"] == arena.backend_proc.pid
    finally:
        mcp.close()
        peer.close()
        sensors_close()


def test_a_link_the_parent_closes_is_reported_at_once_and_the_exit_status_at_the_finish(
        ) -> None:
    arena = ArenaProcess(MissionOptions(realtime=True, port=0, duration=60.0))
    try:
        lost: list[str] = []
        arena.on_lost = lost.append
        t0 = time.monotonic()
        arena.link.close("sensor link: not JSON: b'x'")  # as the link does on a bad line
        assert time.monotonic() - t0 < 0.5  # never waits for the child on the loop
        assert lost == [f"the simulator's process (pid {arena.pid}) lost the sensor link: "
                        "sensor link: not JSON: b'x'"]
    finally:
        arena.finish()
    assert arena.lost == lost[0] + "; then it ended (exit status 0)"


def test_a_failure_after_the_child_started_leaves_no_child(
        monkeypatch: pytest.MonkeyPatch) -> None:
    import ramp.autonomy.hal.hokuyo
    from ramp import cli

    started: list[ArenaProcess] = []
    init = ArenaProcess.__init__

    def recorded(self: ArenaProcess, *args: Any, **kwargs: Any) -> None:
        started.append(self)
        init(self, *args, **kwargs)

    monkeypatch.setattr(ArenaProcess, "__init__", recorded)
    monkeypatch.setattr(ramp.autonomy.hal.hokuyo, "HokuyoLidar", broken)
    try:
        with pytest.raises(RuntimeError, match="broken on purpose"):
            cli.main(["sim", "mission", "--realtime", "--port", "0", "--duration", "5"])
        (arena,) = started
        assert arena.proc.poll() is not None, "the command left its simulator running"
    finally:
        for arena in started:
            arena.finish()


def test_a_close_that_fails_still_ends_the_child(monkeypatch: pytest.MonkeyPatch) -> None:
    run = MissionRun(MissionOptions(realtime=True, port=0, duration=5.0))
    run.build()
    assert run.arena is not None and run.autonomy is not None
    try:
        monkeypatch.setattr(run.autonomy, "close", broken)
        with pytest.raises(RuntimeError, match="broken on purpose"):
            run.close()
        code = run.arena.proc.poll()
    finally:
        run.arena.finish()
    assert code == 0, "the simulator's process was not told to end"


def test_the_phidget_boards_and_the_sim_modules_injections_cross_the_hardware_link() -> None:
    """The Phidget boards stay on the HAL-level sim driver in the backend's process, fed by
    the simulator over the hardware link; what the `sim` module injects goes back over it."""
    arena = ArenaProcess(MissionOptions(realtime=True, port=0, duration=60.0))
    try:
        mcp = socket.create_connection(arena.mcp_address, timeout=5)
        try:
            def volts() -> float:
                m = re.search(r"base:battery\.volt=\(([\d.]+)\)", ask_line(mcp, "base:base.get=()"))
                assert m is not None
                return float(m.group(1))

            fresh = volts()
            assert fresh > 15.0  # the world's battery, read through the Phidget input
            assert ask_line(mcp, "sim:input.set=(base,battery,10.5)") == ""
            assert wait_for(lambda: abs(volts() - fresh) > 0.5, 5), "the override never came"
            assert ask_line(mcp, "sim:bus.unplug=(ble_io)") == ""
            assert wait_for(lambda: "robot:ble.state=(fault)" in ask_line(
                mcp, "robot:robot.get=()"), 5), "unplugging the BLE's board faulted nothing"
            assert "sim:bus.unplugged=(1)" in ask_line(mcp, "sim:sim.get=()")
        finally:
            mcp.close()
    finally:
        arena.finish()
    assert arena.proc.returncode == 0
