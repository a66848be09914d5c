"""Log records of WARNING and above into the recording, as `foxglove.Log` on `/log`.

Foxglove's Log panel shows them beside the plots, so a fault's log line sits on the same
time line as the battery curve and the commands. The handler is cheap and never blocks: it
formats the message and hands it to the recorder's queue, whichever thread logs.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ramp.recorder.recorder import Recorder

#: Python logging levels to Foxglove's LogLevel numbers.
FOXGLOVE_LEVEL = ((logging.CRITICAL, 5), (logging.ERROR, 4), (logging.WARNING, 3),
                  (logging.INFO, 2), (logging.DEBUG, 1))


def foxglove_level(levelno: int) -> int:
    for py, fox in FOXGLOVE_LEVEL:
        if levelno >= py:
            return fox
    return 0


class RecorderLogHandler(logging.Handler):
    """Attach to the `ramp` logger; `now` is the supervisor's clock."""

    def __init__(self, recorder: Recorder, now: Callable[[], float],
                 level: int = logging.WARNING) -> None:
        super().__init__(level)
        self.recorder = recorder
        self.now = now

    def emit(self, record: logging.LogRecord) -> None:
        try:
            message = record.getMessage()
            if record.exc_info and record.exc_info[1] is not None:
                message += f" ({type(record.exc_info[1]).__name__}: {record.exc_info[1]})"
            self.recorder.log(self.now(), foxglove_level(record.levelno), message,
                              record.name, record.pathname, record.lineno or 0)
        except Exception:  # noqa: BLE001 - logging must never raise into the caller
            self.handleError(record)
