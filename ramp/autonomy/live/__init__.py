"""The autonomy's view, live in Foxglove (issue 13 part 4; SPEC 8's channels, streamed).

- `FoxgloveLive` (`foxglove_live.py`): a Foxglove WebSocket server fed like the flight
  recorder (`add_channel`, `publish`), off the tick; `ramp-autonomy --foxglove-port P`.
- `AutonomyView` (`view.py`): the autonomy's own view (state, estimated pose, numbers,
  scans, map) as Foxglove messages on any such sink; `ramp sim mission --record` writes the
  same through the flight recorder, with the simulator's truth beside it.
- `tee` (`tee.py`): one producer feeding a recording and the live view at once.
- `protocol.py`: the `foxglove.websocket.v1` messages, sans I/O.

The server needs the `websockets` library (the `foxglove` extra); importing this package
does not, so a command can offer the option and say what is missing only when it is used.
"""

from ramp.autonomy.live.foxglove_live import (
    DEFAULT_HOST,
    ClientStats,
    FoxgloveLive,
    LiveViewError,
)
from ramp.autonomy.live.tee import Tee, tee
from ramp.autonomy.live.view import AutonomyView

__all__ = ["DEFAULT_HOST", "AutonomyView", "ClientStats", "FoxgloveLive", "LiveViewError",
           "Tee", "tee"]
