"""Control arbitration (SPEC 2.2): at most one owner; others may read and stop, not command."""

from __future__ import annotations


class Control:
    def __init__(self) -> None:
        self.owner: object | None = None
        self.owner_name = "none"

    def may_command(self, client: object) -> bool:
        return self.owner is None or self.owner is client

    def acquire(self, client: object, name: str) -> bool:
        """Make `client` the owner; True when this is a takeover (motion must stop first)."""
        takeover = self.owner is not client
        self.owner = client
        self.owner_name = name
        return takeover

    def release(self, client: object) -> None:
        if self.owner is client:
            self.owner = None
            self.owner_name = "none"
