"""What every fake channel shares: matching, handlers, open/attach/close."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from Phidget22 import _library


class Channel:
    kind = ""

    def __init__(self) -> None:
        self.channel = 0
        self.handlers: dict[str, Callable[..., None]] = {}
        self.is_open = False
        self.attached = False
        self.interval_ms = 250

    def setDeviceSerialNumber(self, n: int) -> None:
        pass

    def setHubPort(self, n: int) -> None:
        pass

    def setChannel(self, n: int) -> None:
        self.channel = n

    def setDeviceLabel(self, s: str) -> None:
        pass

    def setOnAttachHandler(self, h: Callable[..., None]) -> None:
        self.handlers["attach"] = h

    def setOnDetachHandler(self, h: Callable[..., None]) -> None:
        self.handlers["detach"] = h

    def setOnErrorHandler(self, h: Callable[..., None]) -> None:
        self.handlers["error"] = h

    def getMinDataInterval(self) -> int:
        return 1

    def getMaxDataInterval(self) -> int:
        return 60000

    def setDataInterval(self, ms: int) -> None:
        self.interval_ms = ms

    def open(self) -> None:
        self.is_open = True
        _library.schedule(self, 0.01)

    def close(self) -> None:
        self.is_open = False
        self.attached = False

    def _service(self) -> float | None:
        """Called on the library's thread: attach, then the next sample; None: stop."""
        if not self.is_open:
            return None
        if not self.attached:
            self.attached = True
            self.handlers["attach"](self)
        return self._sample()

    def _sample(self) -> float | None:
        return None

    def _emit(self, event: str, *args: Any) -> None:
        handler = self.handlers.get(event)
        if handler is not None:
            handler(self, *args)
