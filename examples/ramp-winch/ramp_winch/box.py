"""The winch box's emulator: its firmware on a loopback TCP socket (`socket://` for the real
driver), speaking the same ASCII protocol and moving the world's signals by their YAML names.
`ramp.emulators` entry `bus.winchbox`."""

from __future__ import annotations

import socket
from typing import Any

STATUS_PERIOD_S = 0.05
SILENCE_STOP_S = 0.5


class WinchBoxEmulator:
    def __init__(self, world: Any, motor: str | None, inputs: dict[int, str]) -> None:
        self.world, self.motor, self.inputs = world, motor, inputs
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(1)
        self.server.setblocking(False)
        self.port = self.server.getsockname()[1]
        self.conn: socket.socket | None = None
        self.buf = b""
        self.heard_at = 0.0
        self.status_at = 0.0

    def service(self, now: float) -> None:
        """Called every tick: accept, read commands, stop on silence, send status."""
        if self.conn is None:
            try:
                self.conn, _ = self.server.accept()
                self.conn.setblocking(False)
                self.heard_at = now
            except BlockingIOError:
                return
        try:
            data = self.conn.recv(4096)
            if not data:
                self._drop()
                return
            self.buf += data
        except BlockingIOError:
            pass
        *lines, self.buf = self.buf.split(b"\n")
        for line in lines:
            if line[:1] == b"M":
                self._set(float(line[1:]))
                self.heard_at = now
        if now - self.heard_at > SILENCE_STOP_S:
            self._set(0.0)
        if now - self.status_at >= STATUS_PERIOD_S:
            self.status_at = now
            bits = "".join("1" if i in self.inputs and self.world.read_digital(self.inputs[i])
                           else "0" for i in (0, 1))
            try:
                self.conn.sendall(f"I{bits}\n".encode("ascii"))
            except OSError:
                self._drop()

    def _set(self, duty: float) -> None:
        if self.motor is not None:
            self.world.set_motor(self.motor, max(-1.0, min(1.0, duty)))

    def _drop(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.conn = None
        self._set(0.0)

    def close(self) -> None:
        self._drop()
        self.server.close()


def emulated_bus(ctx: Any, bc: Any) -> dict[str, Any]:
    """Start the box's emulator for bus `bc`; the real driver connects to it."""
    motor, inputs = None, {}
    for mname, mc in ctx.config.modules.items():
        for dname, dc in mc.devices.items():
            if dc.bus == bc.name and dc.kind == "motor":
                motor = f"{mname}.{dname}"
            elif dc.bus == bc.name and dc.kind == "digital_in":
                inputs[int(dc.channel["input"])] = f"{mname}.{dname}"
    emu = WinchBoxEmulator(ctx.signals, motor, inputs)
    ctx.add_device(emu)
    ctx.add_service(emu.service)
    return {"port": f"socket://127.0.0.1:{emu.port}"}
