"""`tls`: what mutual TLS on the MCP port costs (SPEC 13), and what a handshake flood costs
the tick.

One supervisor (`ramp run --sim`, MARTE) serves TLS with client certificates made by
`ramp.certs`; loopback may still speak plain MCP on the same port, so the baseline is the
same server, the same request (`base:base.get=()`), sequential round trips over plain TCP,
trials alternating with the TLS ones. Then a flood: connections that open and never finish a
handshake, others that send garbage, and full handshakes with a certificate from another CA,
for `tls_flood_s`, while the supervisor's own tick lateness samples show what the loop
lost; the same window without the flood is the baseline. Finally the time from connecting
(a full handshake included) to an operator's `robot:robot.stop=()` being answered, with the
flood running: SPEC 13's "always room for a stop".
"""

from __future__ import annotations

import json
import socket
import ssl
import threading
import time
from pathlib import Path
from typing import Any

import yaml

from bench.common import (
    Settings,
    bench_cpu,
    compare,
    median_of,
    pinned,
    progress,
    recv_line,
    start_supervisor,
    summary,
    versus,
    write_config,
)
from bench.tick import window

REQUEST = b"base:base.get=()\n"


def _pki(workdir: Path) -> Path:
    from ramp.certs.authority import create_ca, issue_client, issue_server

    d = workdir / "pki"
    create_ca(d)
    issue_server(d, "robot", ["127.0.0.1"])
    issue_client(d, "operator1")
    other = workdir / "other"
    create_ca(other, "a stranger's CA")
    issue_client(other, "operator1")
    return d


def _tls_config(workdir: Path, pki: Path) -> Path:
    path = write_config(workdir, "tls")
    data = yaml.safe_load(path.read_text())
    data["server"].update(host="0.0.0.0", max_clients=8,
                          tls={"cert": str(pki / "robot.crt"), "key": str(pki / "robot.key"),
                               "client_ca": str(pki / "ca.crt")})
    data["access"] = {"local": "operator", "identities": {"operator1": "operator"}}
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _context(ca: Path, crt: Path, key: Path) -> ssl.SSLContext:
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.load_verify_locations(ca)
    ctx.load_cert_chain(crt, key)
    return ctx


def _open(port: int, ctx: ssl.SSLContext | None) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", port), timeout=5.0)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return ctx.wrap_socket(sock, server_hostname="127.0.0.1") if ctx is not None else sock


def sequential(port: int, ctx: ssl.SSLContext | None, requests: int,
               warmup: int) -> list[float]:
    """Round trips in µs, each request sent after the previous answer."""
    with _open(port, ctx) as sock:
        for _ in range(warmup):
            sock.sendall(REQUEST)
            recv_line(sock)
        out = []
        for _ in range(requests):
            t0 = time.perf_counter()
            sock.sendall(REQUEST)
            recv_line(sock)
            out.append((time.perf_counter() - t0) * 1e6)
    return out


class Flood:
    """Bad handshakes from threads of this process until `stop()`: half-open connections
    (connect, send nothing), garbage instead of a ClientHello, and full handshakes with a
    stranger's certificate. Counts what it attempted."""

    def __init__(self, port: int, stranger: ssl.SSLContext) -> None:
        self.port, self.stranger = port, stranger
        self.stop_at = threading.Event()
        self.attempts = 0
        self.held: list[socket.socket] = []
        self.threads = [threading.Thread(target=f, daemon=True)
                        for f in (self._half_open, self._garbage, self._stranger)]

    def start(self) -> None:
        for t in self.threads:
            t.start()

    def stop(self) -> None:
        self.stop_at.set()
        for t in self.threads:
            t.join(5.0)
        for s in self.held:
            s.close()

    def _half_open(self) -> None:
        while not self.stop_at.is_set():
            try:
                self.held.append(socket.create_connection(("127.0.0.1", self.port), 1.0))
                self.attempts += 1
            except OSError:
                pass
            if len(self.held) > 200:
                self.held.pop(0).close()
            self.stop_at.wait(0.005)

    def _garbage(self) -> None:
        while not self.stop_at.is_set():
            try:
                with socket.create_connection(("127.0.0.1", self.port), 1.0) as s:
                    s.sendall(b"\x16\x03\x01\x00\x05hello")
                    self.attempts += 1
            except OSError:
                pass
            self.stop_at.wait(0.005)

    def _stranger(self) -> None:
        while not self.stop_at.is_set():
            try:
                with _open(self.port, self.stranger) as s:
                    s.sendall(b"robot:robot.stop=()\n")
                    s.recv(100)
            except (OSError, ssl.SSLError):
                pass
            self.attempts += 1
            self.stop_at.wait(0.005)


def connect_and_stop(port: int, ctx: ssl.SSLContext) -> float:
    """Milliseconds from starting to connect to the answer of an operator's stop."""
    t0 = time.perf_counter()
    with _open(port, ctx) as sock:
        sock.sendall(b"robot:robot.stop=()\n")
        recv_line(sock)
    return (time.perf_counter() - t0) * 1e3


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    pki = _pki(workdir)
    operator = _context(pki / "ca.crt", pki / "operator1.crt", pki / "operator1.key")
    other = workdir / "other"
    stranger = _context(pki / "ca.crt", other / "operator1.crt", other / "operator1.key")
    cpu = bench_cpu()
    child, port, dump = start_supervisor("tls", _tls_config(workdir, pki), workdir, cpu=cpu)
    requests = max(50, settings.rt_requests // 2)
    flood_s = max(1.0, settings.tp_duration_s)
    try:
        plain: list[dict[str, Any]] = []
        tls: list[dict[str, Any]] = []
        with pinned(cpu):
            for trial in range(settings.rt_trials):
                progress(f"tls: trial {trial + 1}/{settings.rt_trials}: {requests} round "
                         "trips plain, then over TLS")
                plain.append(summary(sequential(port, None, requests, settings.rt_warmup)))
                tls.append(summary(sequential(port, operator, requests, settings.rt_warmup)))
        progress(f"tls: {flood_s:g} s quiet, then {flood_s:g} s of handshake flood")
        quiet0 = time.monotonic()
        time.sleep(flood_s)
        quiet1 = time.monotonic()
        flood = Flood(port, stranger)
        flood.start()
        stops: list[float] = []
        try:
            flood0 = time.monotonic()
            while time.monotonic() - flood0 < flood_s:
                stops.append(connect_and_stop(port, operator))
                time.sleep(0.1)
            flood1 = time.monotonic()
        finally:
            flood.stop()
        child.terminate()
    finally:
        child.kill()
    samples = json.loads(dump.read_text())["samples"]
    quiet_late, quiet_over = window(samples, quiet0, quiet1)
    flood_late, flood_over = window(samples, flood0, flood1)
    plain_rtt, tls_rtt = median_of(plain), median_of(tls)
    return {
        "request": REQUEST.decode().strip(),
        "trials": settings.rt_trials,
        "baseline": {"what": "the same supervisor and request over plain TCP on loopback "
                             "(access.local), trials alternating with TLS"},
        "rtt_us": versus(tls_rtt, plain_rtt),
        "tls_over_plain_p50": compare(tls_rtt.get("p50"), plain_rtt.get("p50")),
        "flood": {"seconds": flood_s, "attempts": flood.attempts,
                  "tick_late_us": {"flood": summary(flood_late), "quiet": summary(quiet_late)},
                  "tick_overruns": {"flood": flood_over, "quiet": quiet_over},
                  "operator_connect_to_stop_ms": summary(stops, 2)},
    }
