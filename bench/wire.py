"""Partial hardware-in-the-loop: the real Sabertooth driver writing to a pty this process reads.

Shared by `command_to_wire` and `watchdog_to_wire`. The firmware_like Sabertooth emulator
runs here, unpaced, and every packet is stamped with `time.monotonic()` the moment it is read
off the pty master, so "on the wire" means "out of the driver and through the kernel's tty
layer" (a real 9600-baud UART adds 4.17 ms per packet on top; see platform-limits.md §3).

Two targets speak MCP lines and write to that pty: the supervisor (MARTE config, base_motors
`sim: false` with `port:` the pty, every other bus simulated) and the baseline relay
(`bench.child relay`), which turns each line straight into packets.
"""

from __future__ import annotations

import json
import select
import socket
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from bench.common import (
    PYTHON,
    Child,
    Wheel,
    base_wheels,
    connect,
    load_marte,
    start_supervisor,
    write_config,
)
from firmware_like.pty_link import PtyLink
from firmware_like.sabertooth import SabertoothEmulator
from ramp.hal.sabertooth_codec import duty_command

#: (address, command, data): a motor packet as it reads on the wire.
Key = tuple[int, int, int]
Packet = tuple[float, int, int, int]

TARGETS = ("supervisor", "baseline")


def expected_key(wheel: Wheel, vel: int) -> Key:
    """The packet the driver must send for `wheel.vel=(vel)` (polarity and full duty)."""
    duty = max(-1.0, min(1.0, wheel.polarity * vel / 100.0 * wheel.full_duty))
    command, data = duty_command(wheel.motor, duty)
    return wheel.address, command, data


def channel_of(address: int, command: int) -> tuple[int, int] | None:
    """(address, motor) of a motor packet; None for settings such as command 14."""
    if command in (0, 1):
        return address, 1
    if command in (4, 5):
        return address, 2
    return None


class WireTap:
    """The emulated controllers behind a pty, recording every valid packet with its time."""

    def __init__(self, workdir: Path, name: str = "base_motors") -> None:
        wheels = base_wheels()
        self.link = PtyLink(name, workdir)
        self.packets: list[Packet] = []
        self.emulator = SabertoothEmulator(sorted({w.address for w in wheels}), paced=False,
                                           on_packet=self._on_packet)

    @property
    def path(self) -> str:
        return self.link.path

    def _on_packet(self, t: float, address: int, command: int, data: int) -> None:
        self.packets.append((t, address, command, data))

    def read(self) -> None:
        data = self.link.read_available()
        if data:
            self.emulator.feed(time.monotonic(), data)

    def pump(self, timeout: float, socks: list[socket.socket] | None = None
             ) -> list[socket.socket]:
        """Wait up to `timeout` for the pty or `socks`; read the pty; return readable socks."""
        watched: list[Any] = [self.link.fileno(), *(socks or [])]
        readable, _, _ = select.select(watched, [], [], max(0.0, timeout))
        if self.link.fileno() in readable:
            self.read()
        return [s for s in readable if isinstance(s, socket.socket)]

    def idle(self, seconds: float, socks: list[socket.socket] | None = None) -> bytes:
        """Keep reading the pty (and draining `socks`) for `seconds`; returns socket bytes."""
        got = b""
        end = time.monotonic() + seconds
        while (now := time.monotonic()) < end:
            for sock in self.pump(end - now, socks):
                got += sock.recv(65536)
        return got

    def close(self) -> None:
        self.link.close()


@dataclass
class Target:
    """A process speaking MCP on `port` and writing Sabertooth packets to the tap."""

    kind: str
    child: Child
    port: int
    dump: Path | None

    def stop(self) -> dict[str, Any]:
        """SIGTERM; the supervisor's driver statistics (from its dump), {} for the relay."""
        try:
            self.child.terminate()
        finally:
            self.child.kill()
        if self.dump is None or not self.dump.exists():
            return {}
        stats: dict[str, Any] = json.loads(self.dump.read_text())["bus_stats"]
        return stats


def watchdog_timeout(override: float | None) -> float:
    return float(override if override is not None else load_marte()["watchdog"]["timeout"])


def start_target(kind: str, tap: WireTap, workdir: Path, timeout: float) -> Target:
    if kind == "supervisor":
        config = write_config(workdir, "partial_hil", base_port=tap.path,
                              watchdog_timeout=timeout)
        child, port, dump = start_supervisor("partial_hil", config, workdir)
        target = Target(kind, child, port, dump)
    else:
        wheels = json.dumps([asdict(w) for w in base_wheels()])
        child = Child("relay", [PYTHON, "-m", "bench.child", "relay", "--port", tap.path,
                                "--timeout", str(timeout), "--wheels", wheels], workdir)
        try:
            m = child.expect(r"ready on [\d.]+:(\d+)", 30)
        except BaseException:
            child.kill()
            raise
        target = Target(kind, child, int(m.group(1)), None)
    tap.idle(0.2)  # start-up packets (timeout programming, zeros) out of the way
    return target


def open_client(target: Target) -> socket.socket:
    return connect(target.port)


def read_response(tap: WireTap, sock: socket.socket, timeout: float = 2.0) -> bytes:
    """One response line, reading the pty meanwhile; an error response raises."""
    buf = b""
    end = time.monotonic() + timeout
    while not buf.endswith(b"\n"):
        now = time.monotonic()
        if now >= end:
            raise TimeoutError("no MCP response")
        for s in tap.pump(end - now, [sock]):
            chunk = s.recv(65536)
            if not chunk:
                raise ConnectionError("target closed the connection")
            buf += chunk
    if b".error=(" in buf:
        raise RuntimeError(f"target answered an error: {buf!r}")
    return buf
