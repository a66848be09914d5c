"""A Sabertooth 2x60 in packetized-serial mode, byte for byte, for tests and simulation.

It has its own decoder, written like the firmware's receive loop, and never imports
`ramp`: it is an independent check of the driver, which it meets only through bytes (a pty,
a TCP socket or a direct `feed`).

Firmware behaviour modelled (see shared/reference/hardware-facts.md section 1):
- a byte >= 128 starts a packet (a packet cut short by it is dropped); three more bytes
  complete it; a bad checksum drops it silently (counted here);
- commands 0/1/4/5 (forward/backward), 6/7 (7-bit, 64 = stop) drive the motors; 14 sets the
  serial timeout (100 ms units, 0 = off, off at power-up); 2, 3, 15, 16, 17 are recorded;
  mixed mode 8-13 is recorded and, as on the real controller, switching to it stops the
  independent motors (the mixed outputs themselves are not modelled); anything else is
  counted as ignored;
- with the serial timeout set, no valid packet for the timeout stops both motors; the next
  motor command moves them again;
- packets for addresses this emulator does not own are ignored (other controllers on the
  same wire).
With `paced=True`, a byte only counts as received once its wire time (10 bits at `baud`) has
elapsed after the previous byte, so a 4-byte packet takes 4.17 ms at 9600 baud and a driver
that overruns the wire sees its commands arrive late.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import select
import socket
import sys
import tempfile
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from firmware_like.pty_link import PtyLink

log = logging.getLogger("ramp.sim")

MotorHook = Callable[[int, int, float], None]
PacketHook = Callable[[float, int, int, int], None]

_COMMAND_NAMES = {
    0: "m1 forward", 1: "m1 backward", 2: "min voltage", 3: "max voltage",
    4: "m2 forward", 5: "m2 backward", 6: "m1 7-bit", 7: "m2 7-bit",
    8: "mixed forward", 9: "mixed backward", 10: "turn right", 11: "turn left",
    12: "mixed drive 7-bit", 13: "mixed turn 7-bit", 14: "serial timeout",
    15: "baud rate", 16: "ramping", 17: "deadband",
}
_SETTINGS = {2: "min_voltage", 3: "max_voltage", 15: "baud_rate", 16: "ramping",
             17: "deadband"}
_MIXED = {8: "drive", 9: "drive", 12: "drive", 10: "turn", 11: "turn", 13: "turn"}


@dataclass
class Controller:
    """The state of one emulated controller (one address)."""

    address: int
    duty: list[float] = field(default_factory=lambda: [0.0, 0.0])
    timeout_s: float = 0.0  # 0 = off, as after power-up
    last_valid: float | None = None
    timed_out: bool = False
    mixed: dict[str, float] = field(default_factory=dict)
    settings: dict[str, int] = field(default_factory=dict)


class SabertoothEmulator:
    """One or more controllers sharing a wire. `feed` bytes in, `tick` to run timeouts."""

    def __init__(
        self,
        addresses: Iterable[int] = (128, 129),
        on_motor: MotorHook | None = None,
        baud: int = 9600,
        paced: bool = False,
        history: int = 100_000,
        on_packet: PacketHook | None = None,
    ) -> None:
        self.controllers = {a: Controller(a) for a in addresses}
        self.on_motor = on_motor
        self.on_packet = on_packet
        self.baud = baud
        self.paced = paced
        self.byte_time = 10.0 / baud
        #: (time, address, command, data) of every valid packet for our addresses.
        self.packets: deque[tuple[float, int, int, int]] = deque(maxlen=history)
        self.counters = {
            "bytes": 0, "packets": 0, "bad_checksum": 0, "dropped_bytes": 0,
            "foreign": 0, "ignored": 0, "timeouts": 0, "autobaud": 0,
        }
        self._rx: list[int] = []
        self._wire: deque[tuple[float, int]] = deque()  # paced: (completion time, byte)
        self._wire_free_at = 0.0
        #: No controller can time out before this (a microsecond early, against rounding):
        #: an idle tick is one comparison. -inf: worked out again at the next `_expire`.
        self._quiet_until = -math.inf

    # -- input --------------------------------------------------------------------------------
    def feed(self, now: float, data: bytes) -> None:
        """Bytes that reached the controller's RX pin at `now`."""
        if not self.paced:
            for b in data:
                self._receive(now, b)
            return
        t = max(now, self._wire_free_at)
        for b in data:
            t += self.byte_time
            self._wire.append((t, b))
        self._wire_free_at = t
        self._drain_wire(now)

    def _drain_wire(self, now: float) -> None:
        # A tiny tolerance so a byte due "exactly now" is not held back by float rounding.
        while self._wire and self._wire[0][0] <= now + 1e-12:
            t, b = self._wire.popleft()
            self._receive(t, b)

    def _receive(self, t: float, b: int) -> None:
        self.counters["bytes"] += 1
        rx = self._rx
        if b >= 128:
            if rx:
                if rx == [0xAA]:
                    self.counters["autobaud"] += 1
                else:
                    self.counters["dropped_bytes"] += len(rx)
            self._rx = [b]
            return
        if not rx:
            self.counters["dropped_bytes"] += 1  # noise between packets
            return
        rx.append(b)
        if len(rx) == 4:
            self._rx = []
            address, command, data, check = rx
            if (address + command + data) & 0x7F != check:
                self.counters["bad_checksum"] += 1
                return
            self._packet(t, address, command, data)

    # -- packets ------------------------------------------------------------------------------
    def _packet(self, t: float, address: int, command: int, data: int) -> None:
        ctl = self.controllers.get(address)
        if ctl is None:
            self.counters["foreign"] += 1
            return
        self._expire(t)  # a timeout due before this packet happened first
        self._quiet_until = -math.inf  # its time or its timeout changes below
        self.counters["packets"] += 1
        self.packets.append((t, address, command, data))
        if self.on_packet is not None:
            self.on_packet(t, address, command, data)
        ctl.last_valid = t
        if command in (0, 1, 4, 5, 6, 7):
            ctl.mixed.clear()  # back to independent mode
        if command in (0, 1, 4, 5):
            motor = 1 if command < 4 else 2
            sign = -1.0 if command in (1, 5) else 1.0
            self._set(ctl, motor, sign * data / 127.0)
        elif command in (6, 7):
            value = (data - 64) / (64.0 if data < 64 else 63.0)
            self._set(ctl, 1 if command == 6 else 2, value)
        elif command == 14:
            ctl.timeout_s = data / 10.0
        elif command in _SETTINGS:
            ctl.settings[_SETTINGS[command]] = data
        elif command in _MIXED:
            if not ctl.mixed:  # leaving independent mode stops the motors
                self._set(ctl, 1, 0.0)
                self._set(ctl, 2, 0.0)
            if command in (12, 13):
                value = (data - 64) / (64.0 if data < 64 else 63.0)
            else:
                value = (-1.0 if command in (9, 11) else 1.0) * data / 127.0
            ctl.mixed[_MIXED[command]] = value
        else:
            self.counters["ignored"] += 1

    def _set(self, ctl: Controller, motor: int, duty: float) -> None:
        ctl.duty[motor - 1] = duty
        ctl.timed_out = False
        if self.on_motor is not None:
            self.on_motor(ctl.address, motor, duty)

    # -- time ---------------------------------------------------------------------------------
    def tick(self, now: float) -> None:
        """Advance to `now`: deliver paced bytes whose wire time is over, run timeouts."""
        if self.paced and self._wire:
            self._drain_wire(now)
        self._expire(now)

    def _expire(self, now: float) -> None:
        if now < self._quiet_until:
            return
        quiet = math.inf
        for ctl in self.controllers.values():
            if ctl.timeout_s > 0 and not ctl.timed_out and ctl.last_valid is not None:
                if now - ctl.last_valid > ctl.timeout_s:
                    ctl.timed_out = True
                    self.counters["timeouts"] += 1
                    for motor in (1, 2):
                        ctl.duty[motor - 1] = 0.0
                        if self.on_motor is not None:
                            self.on_motor(ctl.address, motor, 0.0)
                else:
                    quiet = min(quiet, ctl.last_valid + ctl.timeout_s - 1e-6)
        self._quiet_until = quiet

    def power_cycle(self, address: int) -> None:
        """Controller reset (a brown-out): motors stop, the serial timeout is off again."""
        old = self.controllers[address]
        self.controllers[address] = Controller(address)
        self._quiet_until = -math.inf
        for motor in (1, 2):
            if old.duty[motor - 1] != 0.0 and self.on_motor is not None:
                self.on_motor(address, motor, 0.0)

    # -- queries ------------------------------------------------------------------------------
    def duty(self, address: int, motor: int) -> float:
        """The duty motor `motor` (1 or 2) of `address` is running at, -1..1."""
        return self.controllers[address].duty[motor - 1]

    def timeout(self, address: int) -> float:
        """The serial timeout programmed into `address`, in seconds (0 = off)."""
        return self.controllers[address].timeout_s

    def timed_out(self, address: int) -> bool:
        return self.controllers[address].timed_out

    @property
    def backlog(self) -> int:
        """Paced mode: bytes still on the wire (sent but not yet received)."""
        return len(self._wire)


class SabertoothPtyDevice:
    """The emulator behind a `PtyLink`: call `service(now)` from a loop or scheduler task."""

    def __init__(self, link: PtyLink, emulator: SabertoothEmulator) -> None:
        self.link = link
        self.emulator = emulator

    def fileno(self) -> int:
        return self.link.fileno()

    def service(self, now: float) -> int:
        """Feed whatever the driver wrote, then run timeouts; returns the bytes read."""
        data = self.link.read_available()
        if data:
            self.emulator.feed(now, data)
        self.emulator.tick(now)
        return len(data)


# -- standalone ---------------------------------------------------------------------------------
def emulated_bus(ctx: Any, bc: Any) -> dict[str, Any]:
    """`ramp.emulators` entry `bus.sabertooth`: this emulator behind a pty, moving the world's
    motors by their YAML labels; the real driver opens the pty's path (the params returned)."""
    labels = ctx.motor_labels(bc.name, "address", "motor")
    world = ctx.signals

    def on_motor(address: int, motor: int, duty: float) -> None:
        label = labels.get((address, motor))
        if label is not None:
            world.set_motor(label, duty)

    addresses = sorted({a for a, _ in labels}) or [128]
    link = PtyLink(bc.name, ctx.dir)
    emulator = SabertoothEmulator(addresses, on_motor=on_motor, baud=bc.params["baud"],
                                  paced=True)
    ctx.add_pty_device(bc.name, SabertoothPtyDevice(link, emulator))
    log.info("bus %s: Sabertooth emulator (addresses %s) on %s", bc.name,
             ",".join(map(str, addresses)), link.path)
    return {"port": link.path}


def describe(t: float, address: int, command: int, data: int) -> str:
    name = _COMMAND_NAMES.get(command, "unknown")
    return f"{t:10.3f}  {address} {command:3d} {data:3d}  {name}"


def _parse_addresses(text: str) -> list[int]:
    try:
        addresses = [int(a) for a in text.split(",") if a.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of addresses") from None
    if not addresses or any(not 128 <= a <= 135 for a in addresses):
        raise argparse.ArgumentTypeError("addresses are 128-135, comma separated")
    return addresses


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m firmware_like.sabertooth`: an emulated controller on a pty or TCP port."""
    parser = argparse.ArgumentParser(prog="python -m firmware_like.sabertooth",
                                     description=__doc__.split("\n")[0] if __doc__ else None)
    parser.add_argument("--addresses", type=_parse_addresses, default=[128, 129])
    parser.add_argument("--baud", type=int, default=9600)
    parser.add_argument("--paced", action="store_true")
    parser.add_argument("--tcp", type=int, metavar="PORT",
                        help="listen on 127.0.0.1:PORT (0 picks one) instead of a pty")
    parser.add_argument("--dir", help="directory for the pty symlink (default: a temp dir)")
    parser.add_argument("--quiet", action="store_true", help="do not print every packet")
    args = parser.parse_args(argv)

    def log(t: float, address: int, command: int, data: int) -> None:
        print(describe(t, address, command, data), flush=True)

    emu = SabertoothEmulator(args.addresses, baud=args.baud, paced=args.paced,
                             on_packet=None if args.quiet else log)
    try:
        if args.tcp is not None:
            _serve_tcp(emu, args.tcp)
        else:
            _serve_pty(emu, args.dir)
    except KeyboardInterrupt:
        pass
    return 0


def _serve_pty(emu: SabertoothEmulator, directory: str | None) -> None:
    workdir = directory or tempfile.mkdtemp(prefix="sabertooth-")
    link = PtyLink("sabertooth", workdir)
    device = SabertoothPtyDevice(link, emu)
    print(f"sabertooth emulator on {link.path}", flush=True)
    try:
        while True:
            select.select([link.fileno()], [], [], 0.01)
            device.service(time.monotonic())
    finally:
        link.close()
        if directory is None:
            with contextlib.suppress(OSError):
                os.rmdir(workdir)


def _serve_tcp(emu: SabertoothEmulator, port: int) -> None:
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", port))
    server.listen(1)
    print(f"sabertooth emulator on socket://127.0.0.1:{server.getsockname()[1]}", flush=True)
    clients: list[socket.socket] = []
    try:
        while True:
            readable, _, _ = select.select([server, *clients], [], [], 0.01)
            now = time.monotonic()
            for sock in readable:
                if sock is server:
                    conn, _ = server.accept()
                    clients.append(conn)
                    continue
                try:
                    data = sock.recv(65536)
                except OSError:
                    data = b""
                if data:
                    emu.feed(now, data)
                else:
                    clients.remove(sock)
                    sock.close()
            emu.tick(now)
    finally:
        for sock in clients:
            with contextlib.suppress(OSError):
                sock.close()
        server.close()


if __name__ == "__main__":
    sys.exit(main())
