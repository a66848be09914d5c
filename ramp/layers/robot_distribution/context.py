"""What travels down with every request: who sent it and when (the request context).

The server makes one `RequestContext` per message and hands it down with each of the
message's requests, so the robot layer never keeps "the current client" or "now" in hidden
attributes, and an observer (the flight recorder) sees both without asking anyone.
"""

from __future__ import annotations


class Client:
    """What the robot layer needs to know of a connection: its identity (the object itself:
    control and the watchdog compare with `is`) and a printable peer for the log."""

    def __init__(self, peer: str) -> None:
        self.peer = peer

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
