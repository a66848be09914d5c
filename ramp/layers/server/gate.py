"""The gate before MCP (SPEC 13): what a new connection is, and whether it gets a slot.

A connection on a TLS port is first *pending*: its first byte tells a TLS ClientHello (0x16)
from plain MCP, which only loopback may speak; a TLS one then shakes hands without blocking,
driven by the loop's readiness callbacks, under a deadline. A pending connection holds no
client slot and never reaches the MCP parser; at most `MAX_PENDING` are in progress, and a
newcomer replaces the oldest (of its own address first), so a flood of slow or half-open
handshakes churns among itself while an honest client's handshake (a few ms on a LAN) gets
through.

Once it proved who it is, `choose_victim` decides whom it may displace when the slots are
full: an operator or admin is never refused for want of a slot (it evicts the longest-silent
observer or unauthenticated connection), an observer only takes a slot nobody needs.
"""

from __future__ import annotations

import ssl
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from ramp.common.access import RANK
from ramp.layers.robot_distribution import Client

#: Handshakes in progress at once, and how long one may take (SPEC 13).
MAX_PENDING = 16
HANDSHAKE_S = 2.0
TLS_HANDSHAKE_RECORD = 0x16


@dataclass(eq=False)
class Pending:
    """A connection not yet admitted: its first byte unread, or a TLS handshake under way."""

    sock: object  # socket.socket, then ssl.SSLSocket once its first byte said TLS
    fd: int
    address: str
    peer: str
    loopback: bool
    started: float
    deadline: float
    tls: ssl.SSLSocket | None = None
    #: A loopback connection that may yet speak plain MCP: no deadline while it is silent.
    patient: bool = False
    writing: bool = False
    closed: bool = False
    extra: dict[str, object] = field(default_factory=dict)


def certificate_identity(tls: ssl.SSLSocket) -> tuple[str, int | None]:
    """(the client certificate's subject CN, its serial) after a finished handshake."""
    cert = tls.getpeercert() or {}
    cn = ""
    for rdn in cert.get("subject", ()):
        for attr in rdn:
            if attr[0] == "commonName":
                cn = str(attr[1])
    serial_text = cert.get("serialNumber")
    serial = int(str(serial_text), 16) if serial_text else None
    return cn, serial


def evictable(client: Client, authenticated: bool) -> bool:
    """Whom an operator may push out: an observer; and, for one that proved its identity
    with a certificate, a connection that proved nothing (plain loopback)."""
    return RANK.get(client.role, 0) <= RANK["observer"] or (authenticated and not client.tls)


def choose_victim(newcomer_role: str, candidates: Iterable[Client], last_message_at:
                  Callable[[Client], float], protects: Callable[[Client], bool],
                  now: float, silence_s: float, *, roles: bool = True,
                  authenticated: bool = False) -> Client | None:
    """Whom to close so a newcomer of `newcomer_role` gets a slot, or None (busy).

    Everyone: a client silent for `silence_s` that is neither the owner nor commanding
    motion (SPEC 2.2). Where roles are in force (`roles`: an `access:` section), an operator
    or admin besides: the longest-silent observer or (when it is `authenticated` itself)
    unauthenticated connection, preferring those whose loss stops nothing; evicting a
    commander trips the watchdog, which only stops the robot."""
    pool = list(candidates)
    quiet = [c for c in pool if now - last_message_at(c) >= silence_s and not protects(c)]
    if roles and RANK.get(newcomer_role, 0) >= RANK["operator"]:
        weak = [c for c in pool if evictable(c, authenticated)]
        idle = [c for c in weak if not protects(c)]
        for group in (idle, quiet, weak):
            if group:
                return min(group, key=last_message_at)
        return None
    return min(quiet, key=last_message_at) if quiet else None
