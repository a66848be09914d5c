"""A Mosquitto broker of our own on loopback, for tests, `ramp fleet sim` and the bench.

We never hand-roll a broker: this starts Debian's `mosquitto` (2.x) with a generated config
in a temporary directory, on a free loopback port, and waits until it accepts connections.
Two shapes: plain anonymous MQTT (what Mosquitto itself allows on loopback only), or a TLS
listener that requires a client certificate, takes the certificate's CN as the user name and
applies an ACL file (what `ramp fleet init` writes for a real deployment; `mosquitto_conf` is
shared with it so the tested config is the deployed one).

The port is chosen once and kept: `stop()` then `start()` brings the broker back on the same
address, which is how the tests take the broker away from the agents and give it back.
"""

from __future__ import annotations

import contextlib
import getpass
import os
import shutil
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

MOSQUITTO_PATHS = ("/usr/sbin/mosquitto", "/usr/bin/mosquitto", "/usr/local/sbin/mosquitto")


class BrokerError(RuntimeError):
    """The broker could not be started (not installed, or it exited); str() says why."""


@dataclass(frozen=True)
class BrokerTls:
    """The broker's side of mutual TLS: the CA that signs clients, the broker's own pair,
    and the ACL file applied to the certificates' CNs."""

    ca: Path
    cert: Path
    key: Path
    acl: Path | None = None


def find_mosquitto() -> str | None:
    """The mosquitto executable, or None when the package is not installed."""
    found = shutil.which("mosquitto")
    if found:
        return found
    return next((p for p in MOSQUITTO_PATHS if os.access(p, os.X_OK)), None)


def mosquitto_conf(port: int, *, host: str = "127.0.0.1", tls: BrokerTls | None = None,
                   log_file: Path | None = None, run_as_me: bool = True) -> str:
    """The text of a mosquitto.conf with one listener: anonymous plain MQTT, or TLS that
    requires a client certificate whose CN is the user name, checked against the ACL.
    `run_as_me`: a broker we start as root stays root (it reads our private temp files);
    a deployed config leaves that to Debian's service (the `mosquitto` user)."""
    lines = ["# Written by RAMP (ramp/fleet/broker.py).", "per_listener_settings false",
             "persistence false"]
    if run_as_me and os.geteuid() == 0:
        # Run as root, mosquitto drops to the `mosquitto` user, which cannot read our 0600
        # keys in a private directory; stay the user that started it.
        lines.append(f"user {getpass.getuser()}")
    if log_file is not None:
        lines += [f"log_dest file {log_file}", "log_type error", "log_type warning",
                  "log_type notice", "log_type information", "connection_messages true"]
    lines.append(f"listener {port} {host}")
    if tls is None:
        lines.append("allow_anonymous true")
    else:
        lines += [f"cafile {tls.ca}", f"certfile {tls.cert}", f"keyfile {tls.key}",
                  "tls_version tlsv1.2", "require_certificate true",
                  "use_identity_as_username true", "allow_anonymous false"]
        if tls.acl is not None:
            lines.append(f"acl_file {tls.acl}")
    return "\n".join(lines) + "\n"


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nothing listens on now (the kernel's pick)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def accepts(host: str, port: int, timeout: float = 0.2) -> bool:
    """True when a TCP connect to host:port succeeds now."""
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


class LocalBroker:
    """One mosquitto process on loopback: `start()`, `stop()`, `address`, a context manager.

    `port=0` picks a free port at the first start and keeps it. The config, log and (for
    TLS) nothing else live in a temporary directory removed by `close()`."""

    def __init__(self, *, tls: BrokerTls | None = None, host: str = "127.0.0.1",
                 port: int = 0, start_timeout: float = 10.0) -> None:
        self.tls = tls
        self.host = host
        self.port = port
        self.start_timeout = start_timeout
        self._dir = Path(tempfile.mkdtemp(prefix="ramp-mosquitto-"))
        self.conf_path = self._dir / "mosquitto.conf"
        self.log_path = self._dir / "mosquitto.log"
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def address(self) -> str:
        """`HOST:PORT`, as `fleet.broker` and `--broker` take it."""
        return f"{self.host}:{self.port}"

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def log(self) -> str:
        """What mosquitto logged so far (for a failing test's message)."""
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def start(self) -> LocalBroker:
        """Start mosquitto and return once it accepts TCP connections; BrokerError if it
        cannot (not installed, port taken, bad config: mosquitto's own words)."""
        if self.running:
            return self
        exe = find_mosquitto()
        if exe is None:
            raise BrokerError("mosquitto is not installed (Debian: apt-get install mosquitto)")
        tries = 3 if self.port == 0 else 1
        last = ""
        for _ in range(tries):
            port = self.port or free_port(self.host)
            self.conf_path.write_text(mosquitto_conf(port, host=self.host, tls=self.tls,
                                                     log_file=self.log_path))
            proc = subprocess.Popen([exe, "-c", str(self.conf_path)], stdin=subprocess.DEVNULL,
                                    stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                    start_new_session=True)
            deadline = time.monotonic() + self.start_timeout
            while time.monotonic() < deadline and proc.poll() is None:
                if accepts(self.host, port):
                    self.proc, self.port = proc, port
                    return self
                time.sleep(0.02)  # start-up of a child process, not control work
            if proc.poll() is None:
                proc.kill()
            _, err = proc.communicate(timeout=5)
            last = (err or b"").decode(errors="replace").strip() or self.log()[-2000:]
        raise BrokerError(f"mosquitto did not start on {self.host}:{self.port or '?'}: {last}")

    def stop(self) -> None:
        """Stop mosquitto (SIGTERM, then SIGKILL after 5 s); the port is kept for a restart."""
        proc, self.proc = self.proc, None
        if proc is None:
            return
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
        if proc.stderr is not None:
            proc.stderr.close()

    def kill(self) -> None:
        """SIGKILL: the broker vanishes without a word (a crash, a pulled cable)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
        self.stop()

    def close(self) -> None:
        """Stop and remove the temporary directory."""
        self.stop()
        with contextlib.suppress(OSError):
            shutil.rmtree(self._dir)

    def __enter__(self) -> LocalBroker:
        return self.start()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
