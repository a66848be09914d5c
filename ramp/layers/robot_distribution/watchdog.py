"""The motion watchdog (SPEC 2.2).

Armed by an accepted motion request, whose sender becomes the feeder; fed only by the
feeder's complete messages, so a monitoring client's polling never keeps a dead driver's
motors running; disarmed by a stop that leaves nothing moving; tripped on expiry or when the
feeder disconnects, until the next accepted motion request.
"""

from __future__ import annotations

from typing import Literal

State = Literal["idle", "armed", "tripped"]

#: Shortest timeout accepted (s): a few ticks. Anything shorter trips between two messages of
#: a healthy client, and `1e-300` used to be accepted and shown as `0.0`.
MIN_TIMEOUT_S = 0.05
MAX_TIMEOUT_S = 60.0


class Watchdog:
    def __init__(self, timeout: float = 1.0) -> None:
        self.timeout = timeout
        self.state: State = "idle"
        self.feeder: object | None = None
        self.last_feed = 0.0
        self.trips = 0

    def arm(self, client: object, now: float) -> None:
        self.state = "armed"
        self.feeder = client
        self.last_feed = now

    def disarm(self) -> None:
        """Nothing moves any more: nothing to guard."""
        if self.state == "armed":
            self.state = "idle"
        self.feeder = None

    def reset(self) -> None:
        """An accepted motion request left nothing moving: idle, whatever it was (a trip is
        over once a new motion request is accepted)."""
        self.state = "idle"
        self.feeder = None

    def feed(self, client: object, now: float) -> None:
        if self.state == "armed" and client is self.feeder:
            self.last_feed = now

    def expired(self, now: float) -> bool:
        """True once when the armed timer runs out (the caller stops everything)."""
        if self.state == "armed" and now - self.last_feed >= self.timeout:
            self._trip()
            return True
        return False

    def trip(self) -> None:
        """Motion was stopped under the robot (a stalled loop): `tripped` until the next
        accepted motion request, whatever the state was."""
        self._trip()

    def client_lost(self, client: object) -> bool:
        """True when the lost client was feeding an armed watchdog (the caller stops)."""
        if self.state == "armed" and client is self.feeder:
            self._trip()
            return True
        if client is self.feeder:
            self.feeder = None
        return False

    def _trip(self) -> None:
        self.state = "tripped"
        self.trips += 1
