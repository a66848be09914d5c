"""`ramp sim mission --record FILE.mcap [--foxglove-port P]`: the autonomy's view of a run,
with the simulator's truth beside it, for Foxglove (SPEC 8).

The autonomy's own view (its state changes, estimated pose, numbers, scans and map) is
`ramp.autonomy.live.view.AutonomyView`, the very messages `ramp-autonomy --foxglove-port`
streams on the robot; this adds what only a simulator knows:

| topic | schema | one message per |
|---|---|---|
| `/pose/true` | `foxglove.PoseInFrame` | 0.1 s: the world's truth (frame `arena`) |
| `/mission/numbers` | `ramp.MissionNumbers` | `true_bin_kg`, `true_delivered_kg`, `true_lift` |
|  |  | beside the autonomy's pose confidence, bin load, delivered and lift |

Written with the flight recorder (`ramp.recorder.Recorder`: its writer thread, its MCAP
framing) and/or streamed live (`FoxgloveLive`), through one `tee`. Times: the simulation's
clock, mapped to wall-clock nanoseconds once at the start (the recorder's `TimeBase`, shared
with the live view).
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from ramp.autonomy.live.tee import Sink, tee
from ramp.autonomy.live.view import POSE_IN_FRAME, AutonomyView, pose_message, stamp
from ramp.recorder.config import RecorderConfig
from ramp.recorder.recorder import Recorder
from ramp.recorder.schemas import ChannelSpec

if TYPE_CHECKING:
    from ramp.simulation.mission import MissionRun
    from ramp.statemachine import StateChange

POSE_TRUE = ChannelSpec("/pose/true", "foxglove.PoseInFrame", POSE_IN_FRAME)


class MissionRecorder:
    """A `MissionRun` observer writing the autonomy's view and the truth into one MCAP file
    (`path`), streaming them to a live view (`live`, a started or unstarted `FoxgloveLive`),
    or both."""

    def __init__(self, path: str | Path | None, *, live: Sink | None = None) -> None:
        self.path = Path(path) if path is not None else None
        self._dir: Path | None = None
        self.recorder: Recorder | None = None
        if self.path is not None:
            self._dir = Path(tempfile.mkdtemp(prefix="ramp-mission-rec-"))
            self.recorder = Recorder(RecorderConfig(str(self._dir), max_mb=1e6, keep=1))
        self.sink = tee(self.recorder, live)
        self.sink.add_channel(POSE_TRUE)
        self.view: AutonomyView | None = None
        self._started = False

    def start(self, now: float) -> None:
        """Open the file and listen (also done by `started`; call it first to know the live
        view's port before the run)."""
        if not self._started:
            self._started = True
            self.sink.start(now)

    def abandon(self) -> None:
        """The run will not happen (the live view could not listen): close, keep no file."""
        self.sink.close()
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)

    # -- MissionRun's hooks ---------------------------------------------------------------------
    def started(self, run: MissionRun) -> None:
        assert run.clock is not None and run.autonomy is not None
        self.view = AutonomyView.watching(self.sink, run.autonomy)
        self.start(run.clock.now())

    def changed(self, run: MissionRun, change: StateChange) -> None:
        pass  # the view has the mission's own listener

    def sampled(self, run: MissionRun, now: float) -> None:
        w = run.world
        self.sink.publish(now, POSE_TRUE.topic,
                          pose_message(stamp(self.sink.timebase, now), w.x, w.y, w.yaw))
        if self.view is not None:
            self.view.sample(now, truth={"true_bin_kg": w.bin_kg,
                                         "true_delivered_kg": w.delivered_kg,
                                         "true_lift": w.lift_pos})

    def finished(self, run: MissionRun) -> None:
        if self.view is not None:
            self.view.close()
        self.sink.close()
        if self._dir is None or self.path is None:
            return
        files = sorted(self._dir.glob("*.mcap"))
        if files:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(str(files[-1]), self.path)
        shutil.rmtree(self._dir, ignore_errors=True)
