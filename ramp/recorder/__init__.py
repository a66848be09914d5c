"""The flight recorder (SPEC section 8): MCAP files of every run, and `ramp log`.

`Recorder` is what the supervisor feeds (cheap calls from the tick; the files are written by
a thread); `RecorderConfig` is `ramp.yaml`'s `recorder:` block; `ramp.recorder.logcli` holds
the `ramp log summary` and `ramp log plot` commands, which read the files back.

The names below are imported on first use, so `ramp run` without recording and `ramp check`
do not pay for loading the MCAP writer and its compressors.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ramp.recorder.config import RECORDER_FIELDS, RecorderConfig
    from ramp.recorder.recorder import SAMPLE_HZ, Recorder, RecorderError, rows_dict
    from ramp.recorder.schemas import EVENT_KINDS, ChannelSpec

_WHERE = {"RECORDER_FIELDS": "config", "RecorderConfig": "config", "SAMPLE_HZ": "recorder",
          "Recorder": "recorder", "RecorderError": "recorder", "rows_dict": "recorder",
          "EVENT_KINDS": "schemas", "ChannelSpec": "schemas"}
__all__ = ["EVENT_KINDS", "RECORDER_FIELDS", "SAMPLE_HZ", "ChannelSpec", "Recorder",
           "RecorderConfig", "RecorderError", "rows_dict"]


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"ramp.recorder.{_WHERE[name]}"), name)
