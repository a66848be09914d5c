"""Test harness: a real Supervisor on a virtual clock, spoken to over real TCP sockets.

The test thread drives both sides: it sends bytes on a client socket, then lets the
supervisor's scheduler service I/O and tick, so each step is deterministic and a simulated
second costs milliseconds.
"""

from __future__ import annotations

import os
import re
import select
import signal
import socket
import subprocess
import sys
import time
from typing import Any

from ramp.clock import VirtualClock
from ramp.config import BusConfig, Config, parse_config
from ramp.hal.interfaces import Bus
from ramp.hal.simio import SimBus
from ramp.runtime import build


class FakeWorld:
    """A SimWorld made of dicts: what the sim driver wrote, and what tests want it to read."""

    def __init__(self) -> None:
        self.motors: dict[str, float] = {}
        self.analog: dict[str, float] = {}
        self.digital: dict[str, bool] = {}
        self.outputs: dict[str, bool] = {}
        self.bridge: dict[str, float] = {}
        self.unplugged: set[str] = set()

    def set_motor(self, name: str, duty: float) -> None:
        self.motors[name] = duty

    def read_analog(self, name: str) -> float:
        return self.analog.get(name, 0.0)

    def read_digital(self, name: str) -> bool:
        return self.digital.get(name, False)

    def write_digital(self, name: str, on: bool) -> None:
        self.outputs[name] = on

    def read_bridge(self, name: str) -> float:
        return self.bridge.get(name, 0.0)

    def bus_present(self, bus: str) -> bool:
        return bus not in self.unplugged


def config_from(text: str) -> Config:
    cfg, errors = parse_config(text, "test.yaml")
    assert not errors, "\n".join(str(e) for e in errors)
    assert cfg is not None
    return cfg


DEMO_YAML = """
server: {host: 127.0.0.1, port: 0, max_clients: 4}
watchdog: {timeout: 0.5}
buses:
  io: {driver: sim}
  io2: {driver: sim}
modules:
  demo: {motor: {bus: io}, lamp: {bus: io}}
  arm: {type: demo, motor: {bus: io2}, lamp: {bus: io2}}
"""


class TestClient:
    """A raw TCP client whose reads pump the supervisor until a line arrives."""

    def __init__(self, harness: Harness) -> None:
        self.h = harness
        host, port = harness.sup.server.address
        self.sock = socket.create_connection((host, port))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buf = b""
        self.closed = False
        harness.pump_io()

    def send(self, data: bytes | str) -> None:
        self.sock.sendall(data.encode() if isinstance(data, str) else data)

    def line(self, max_polls: int = 2000) -> str:
        """The next response line (without `\\n`), pumping the server meanwhile."""
        for _ in range(max_polls):
            if b"\n" in self.buf:
                line, self.buf = self.buf.split(b"\n", 1)
                return line.decode()
            self.h.pump_io()
            r, _, _ = select.select([self.sock], [], [], 0.001)
            if r:
                chunk = self.sock.recv(65536)
                if not chunk:
                    self.closed = True
                    raise ConnectionError("server closed the connection")
                self.buf += chunk
        raise TimeoutError("no response line")

    def ask(self, text: str) -> str:
        self.send(text + "\n")
        return self.line()

    def close(self) -> None:
        self.sock.close()
        self.h.pump_io()


class Harness:
    def __init__(self, yaml_text: str = DEMO_YAML, world: Any = None,
                 bus_factory: Any = None, observer: Any = None, recorder: Any = None,
                 host: str = "127.0.0.1") -> None:
        self.clock = VirtualClock()
        self.world = world if world is not None else FakeWorld()
        self.config = config_from(yaml_text)
        self.sup = build(self.config, self.clock, bus_factory or self._bus,
                         host=host, port=0, observer=observer, recorder=recorder)
        self.sup.start()
        self.clients: list[TestClient] = []

    def _bus(self, bc: BusConfig) -> Bus:
        return SimBus(bc.name, dict(bc.params), world=self.world)

    def connect(self) -> TestClient:
        before = self.sup.server.accepted + self.sup.server.refused
        c = TestClient(self)
        self.clients.append(c)
        for _ in range(200):
            if self.sup.server.accepted + self.sup.server.refused > before:
                break
            self.pump_io()
        return c

    def pump_io(self) -> None:
        self.sup.scheduler.poll_io(0.0)

    def advance(self, seconds: float) -> None:
        self.sup.scheduler.run_for(seconds)

    def close(self) -> None:
        for c in self.clients:
            c.sock.close()
        self.sup.shutdown()


REPO = __import__("pathlib").Path(__file__).resolve().parent.parent
MARTE_YAML = (REPO / "ramp.yaml").read_text()
SCOUT_YAML = (REPO / "examples" / "robots" / "scout.yaml").read_text()
#: The robots the contract tests run on (SPEC 10): name -> (config text, a MARTE model?).
ROBOTS = {"marte": (MARTE_YAML, True), "scout": (SCOUT_YAML, False)}


class SimHarness(Harness):
    """The MARTE config on the physics model through the `--sim` backplane
    (`ramp.simulation.backplane.SimBackplane`)."""

    def __init__(self, yaml_text: str = MARTE_YAML, wire_level: bool = True,
                 seed: int = 0, recorder: Any = None, observer: Any = None,
                 marte: bool = True, latch_state: Any = None) -> None:
        """`marte`: hand the backplane a seeded MARTE model (False: the world is what the
        config's emulators build, as for Scout; `world` is then the composed world).
        `latch_state`: a `LatchState` kept across harnesses (a restart)."""
        from firmware_like.marte import MarteWorld
        from ramp.simulation.backplane import SimBackplane

        self.clock = VirtualClock()
        self.config = config_from(yaml_text.replace("port: 5577", "port: 0"))
        world = MarteWorld(seed=seed) if marte else None
        self.backplane = SimBackplane(self.config, world, wire_level=wire_level)
        self.world = self.backplane.world
        self.sup = build(self.config, self.clock, self.backplane.bus_factory,
                         host="127.0.0.1", port=0, recorder=recorder, observer=observer)
        self.backplane.attach(self.sup)
        self.sup.latch_state = latch_state
        self.sup.start()
        self.sup.settle()
        self.clients = []

    def close(self) -> None:
        super().close()
        self.backplane.close()


def ask_line(sock: socket.socket, text: str) -> str:
    """Send one message on a blocking socket and read its response line."""
    sock.sendall(text.encode() + b"\n")
    buf = b""
    while not buf.endswith(b"\n"):
        chunk = sock.recv(65536)
        assert chunk, "server closed"
        buf += chunk
    return buf.decode().rstrip("\n")


def start_ramp(args: list[str], env: dict[str, str] | None = None,
               stderr: int = subprocess.PIPE) -> tuple[subprocess.Popen[str], str, int]:
    """`ramp run ARGS` as a process, once it printed its ready line: (process, host, port).
    The process is killed if it never gets ready."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "ramp.cli", "run", *args], cwd=REPO, text=True,
        stdout=subprocess.PIPE, stderr=stderr, env={**os.environ, **(env or {})})
    assert proc.stdout is not None
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        r, _, _ = select.select([proc.stdout], [], [], 0.5)
        if r:
            line = proc.stdout.readline()
            m = re.match(r"ramp: ready on ([\d.]+):(\d+)", line)
            if m:
                return proc, m.group(1), int(m.group(2))
            if not line and proc.poll() is not None:
                break
    proc.kill()
    raise AssertionError(f"no ready line; stderr: {proc.communicate()[1]}")


def robot_harness(name: str, **kwargs: Any) -> SimHarness:
    """One of `ROBOTS` on its emulators."""
    text, marte = ROBOTS[name]
    return SimHarness(text, marte=marte, **kwargs)


def value(resp: str, key: str) -> str:
    """The first value of `key` (`MODULE:DEVICE.PROPERTY`) in a response line."""
    m = re.search(re.escape(key) + r"=\(([^)]*)\)", resp)
    assert m, f"{key} not in {resp}"
    return m.group(1)


def end_process(proc: subprocess.Popen[Any], sig: int = signal.SIGTERM,
                timeout: float = 10.0) -> tuple[Any, Any]:
    """End a process a test started: `sig`, then SIGKILL if it has not gone in `timeout` s.
    Returns `communicate()`'s (stdout, stderr): its pipes are read meanwhile, so a shutdown
    that writes much cannot block on them. The exit code stays in `proc.returncode`."""
    proc.send_signal(sig)  # Popen sends nothing to a process it has seen exit
    try:
        return proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.communicate()


def stop_process(proc: subprocess.Popen[Any]) -> None:
    """End a process a test started: SIGTERM, then SIGKILL if it has not gone in 5 s. It waits
    for the exit, not for the end of the pipes (which `end_process` reads): nothing is read."""
    proc.terminate()
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=5)
    if proc.stdout is not None:
        proc.stdout.close()
