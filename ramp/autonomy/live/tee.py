"""`tee(...)`: one producer feeding several channel sinks (a recording and a live view).

A sink is anything with the flight recorder's publishing shape: `start(now)`,
`add_channel(spec)`, `publish(t, topic, payload)`, `close()` and a `timebase` with
`ns(t)` once started (`ramp.recorder.Recorder`, `FoxgloveLive`), and optionally
`wants(topic)` (`FoxgloveLive`: does anyone watch it now). The tee has the same shape, so
code written for a Recorder takes a tee unchanged:

    sink = tee(recorder_or_None, live_or_None)   # the absent ones are left out
    sink.add_channel(spec); sink.start(clock.now()); sink.publish(t, topic, payload)

The first sink's time base stamps everything: the later sinks that have none yet are given
it before they start, so a recording and the live view carry the same nanoseconds.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol


class Sink(Protocol):
    def start(self, now: float) -> object: ...

    def add_channel(self, spec: Any) -> None: ...

    def publish(self, t: float, topic: str, payload: Mapping[str, Any]) -> None: ...

    def close(self) -> None: ...


class Tee:
    """Forwards each call to every sink, in order."""

    def __init__(self, sinks: list[Sink]) -> None:
        self.sinks = sinks

    @property
    def timebase(self) -> Any:
        """The first sink's time base (None before `start`, or with no sink)."""
        return getattr(self.sinks[0], "timebase", None) if self.sinks else None

    def start(self, now: float) -> None:
        shared = None
        for sink in self.sinks:
            if shared is not None and getattr(sink, "timebase", False) is None:
                sink.timebase = shared  # type: ignore[attr-defined]
            sink.start(now)
            shared = shared or getattr(sink, "timebase", None)

    def add_channel(self, spec: Any) -> None:
        for sink in self.sinks:
            sink.add_channel(spec)

    def publish(self, t: float, topic: str, payload: Mapping[str, Any]) -> None:
        for sink in self.sinks:
            sink.publish(t, topic, payload)

    def wants(self, topic: str) -> bool:
        """Whether any sink takes `topic` now (one that cannot say takes everything)."""
        for sink in self.sinks:
            wants = getattr(sink, "wants", None)
            if wants is None or wants(topic):
                return True
        return False

    def close(self) -> None:
        for sink in self.sinks:
            sink.close()

    def __enter__(self) -> Tee:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def tee(*sinks: Sink | None) -> Tee:
    """A sink feeding every given sink (None ones are skipped; none at all publishes
    nowhere)."""
    return Tee([s for s in sinks if s is not None])
