"""Rate-limit repeated log lines: the same logger and template within a window are counted,
not printed.

A client that connects and closes in a loop made `ramp run` write 1,140 WARNING lines in
10 s: the journal filled with one fact, and a real problem in between scrolled away. The
`RepeatFilter` on the console handler lets the first `burst` lines of a kind through in each
`window`, counts the rest, and says how many it held back on the next line of that kind
that passes (`... (1,135 more like this in the last 10 s not shown)`). A kind is the logger
and the message's text with its numbers masked: the peers and counts differ, the fact does
not (`client 127.0.0.1:41234 connected (3 of 8)`), while two facts one template can say stay
apart (`disconnected: closed by client` is not `disconnected: not reading its responses`).
The flight recorder's handler sees every line (it is not behind this filter), so nothing is
lost to a later `ramp log summary`.

The window is measured in the record's wall time (`record.created`): logging is no control
work, and what a reader sees on a terminal is wall time.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass

_DIGITS = re.compile(r"\d+")

#: Lines of one kind let through in each window.
BURST = 5
#: The window, seconds.
WINDOW_S = 10.0
#: Kinds remembered at most (a flood of distinct templates must not grow memory).
MAX_KINDS = 1024


@dataclass
class _Kind:
    start: float
    passed: int = 0
    held: int = 0


class RepeatFilter(logging.Filter):
    """A handler filter: see the module docstring."""

    def __init__(self, burst: int = BURST, window: float = WINDOW_S) -> None:
        super().__init__()
        self.burst, self.window = burst, window
        self._kinds: dict[tuple[str, int, str], _Kind] = {}
        #: Lines held back so far, all kinds (for tests and `ramp run`'s exit line).
        self.suppressed = 0

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.CRITICAL:
            return True
        key = (record.name, record.levelno, _DIGITS.sub("#", record.getMessage()))
        now = record.created
        kind = self._kinds.get(key)
        if kind is None or now - kind.start >= self.window:
            held = kind.held if kind is not None else 0
            if kind is None and len(self._kinds) >= MAX_KINDS:
                self._forget(now)
            self._kinds[key] = _Kind(now, 1)
            if held:
                self._add_count(record, held)
            return True
        if kind.passed < self.burst:
            kind.passed += 1
            return True
        kind.held += 1
        self.suppressed += 1
        return False

    def _add_count(self, record: logging.LogRecord, held: int) -> None:
        """Say on `record` how many of its kind were held back. The record is changed in
        place (a filter cannot hand a copy back before Python 3.12): put this filter on the
        handler that runs last, the root's console handler, as `ramp run` does; the
        recorder's handler on the `ramp` logger has seen the record by then."""
        record.msg = f"{record.getMessage()} ({held:,} more like this in the last " \
                     f"{self.window:g} s not shown)"
        record.args = None

    def _forget(self, now: float) -> None:
        for key in [k for k, v in self._kinds.items() if now - v.start >= self.window]:
            del self._kinds[key]
        if len(self._kinds) >= MAX_KINDS:
            self._kinds.clear()


def install(handler: logging.Handler) -> RepeatFilter:
    """Put a `RepeatFilter` on `handler` (the console's), once; returns it."""
    for f in handler.filters:
        if isinstance(f, RepeatFilter):
            return f
    f = RepeatFilter()
    handler.addFilter(f)
    return f
