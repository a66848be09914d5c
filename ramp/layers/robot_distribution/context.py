"""What travels down with every request: who sent it and when (the request context).

The server makes one `RequestContext` per message and hands it down with each of the
message's requests, so the robot layer never keeps "the current client" or "now" in hidden
attributes, and an observer (the flight recorder) sees both without asking anyone.
"""

from __future__ import annotations

import math


class Client:
    """What the robot layer needs to know of a connection: its identity (the object itself:
    control and the watchdog compare with `is`), a printable peer for the log, and what the
    watchdog keeps of it: when its last complete message arrived, and its own timeout (SPEC
    2.2: `robot:watchdog.timeout=(s)` sets the sender's, for as long as it is connected)."""

    def __init__(self, peer: str, identity: str = "local", role: str = "admin",
                 tls: bool = False) -> None:
        self.peer = peer
        #: Who it is (SPEC 13): its certificate's CN over TLS, else `local`.
        self.identity = identity
        #: What it may do: observer, operator or admin (`ramp.config.access.ROLES`).
        self.role = role
        #: It proved its identity with a client certificate (mutual TLS).
        self.tls = tls
        #: Clock time of its last complete message (any: a heartbeat, an erroneous one).
        self.last_heard = -math.inf
        #: Its own watchdog timeout (s); None: the configured default.
        self.timeout: float | None = None

    def __repr__(self) -> str:
        return f"Client({self.peer})"


class RequestContext:
    """One message's sender and arrival time (clock seconds), for each of its requests."""

    __slots__ = ("client", "now")

    def __init__(self, client: Client, now: float) -> None:
        self.client = client
        self.now = now

    def __repr__(self) -> str:
        return f"RequestContext({self.client!r}, {self.now:.6f})"
