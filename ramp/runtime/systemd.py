"""systemd's notify protocol (sd_notify), spoken directly over its datagram socket.

READY=1 once serving, WATCHDOG=1 only while ticks run on time (a stalled loop stops petting
and systemd restarts the service), STATUS= with a one-line health summary, STOPPING=1 on
shutdown. Without NOTIFY_SOCKET (not under systemd) every call is a no-op.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Mapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ramp.runtime.supervisor import Supervisor

log = logging.getLogger("ramp.systemd")

STATUS_PERIOD = 5.0


class SystemdNotifier:
    def __init__(self, env: Mapping[str, str] | None = None) -> None:
        env = os.environ if env is None else env
        self.address = env.get("NOTIFY_SOCKET", "")
        self.sock: socket.socket | None = None
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        self.watchdog_s = 0.0
        if usec.isdigit() and (not pid or pid == str(os.getpid())):
            self.watchdog_s = int(usec) / 1e6
        self._last_pet = -1e9
        self._last_status = -1e9
        self._sup: Supervisor | None = None
        self.late_limit = 0.25
        if self.address:
            addr = "\0" + self.address[1:] if self.address.startswith("@") else self.address
            try:
                self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
                self.sock.connect(addr)
                self.sock.setblocking(False)
            except OSError as exc:
                log.warning("NOTIFY_SOCKET %s unusable: %s", self.address, exc)
                self.sock = None

    @property
    def enabled(self) -> bool:
        return self.sock is not None

    def send(self, message: str) -> bool:
        if self.sock is None:
            return False
        try:
            self.sock.send(message.encode())
        except OSError as exc:
            log.warning("sd_notify failed: %s", exc)
            return False
        return True

    def ready(self, status: str) -> None:
        self.send(f"READY=1\nSTATUS={status}")

    def stopping(self) -> None:
        self.send("STOPPING=1\nSTATUS=stopping: motors to zero")
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def attach(self, sup: Supervisor) -> None:
        """Pet the watchdog and refresh STATUS from a scheduler task."""
        if not self.enabled:
            return
        self._sup = sup
        self.late_limit = sup.config.stall_limit
        divisor = max(1, round(sup.scheduler.rate_hz / 10.0))
        sup.scheduler.add_task("systemd", sup.scheduler.rate_hz / divisor, self.tick)

    def tick(self, now: float, dt: float) -> None:
        sup = self._sup
        if sup is None:
            return
        stats = sup.scheduler.stats
        recent_late = stats.late_us[-1] / 1e6 if stats.late_us else 0.0
        if (self.watchdog_s and now - self._last_pet >= self.watchdog_s / 2
                and recent_late < self.late_limit):
            self.send("WATCHDOG=1")
            self._last_pet = now
        if now - self._last_status >= STATUS_PERIOD:
            self.send(f"STATUS={summary(sup)}")
            self._last_status = now


def summary(sup: Supervisor) -> str:
    """`modules base=ok ble=fault; clients 2; owner none; watchdog idle; late p99 180us`."""
    mods = " ".join(f"{n}={s.state}" for n, s in sup.slots.items()) or "none"
    p50, p99, mx = sup.scheduler.stats.percentiles()
    return (f"modules {mods}; clients {len(sup.server.clients)}; owner "
            f"{sup.robot.control.owner_name}; watchdog {sup.watchdog.state}; "
            f"late p99 {p99:.0f}us; overruns {sup.scheduler.stats.overruns}")
