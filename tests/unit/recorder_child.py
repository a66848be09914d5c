"""A process that records steadily on the wall clock until it is killed (for the SIGKILL
test): 100 commands and 10 health samples a second, as a supervisor's tick would."""

from __future__ import annotations

import sys
import time

from ramp.mcp.messages import Response
from ramp.recorder import Recorder, RecorderConfig


def main(directory: str) -> None:
    rec = Recorder(RecorderConfig(directory))
    rec.start(time.monotonic())
    print(f"recording {rec.path}", flush=True)
    k = 0
    while True:
        now = time.monotonic()
        rec.command(now, "base_motors", "base.lf_wheel", (k % 200 - 100) / 100)
        if k % 10 == 0:
            rec.health(now, [Response("robot", "robot", "uptime", (k / 100,))])
        k += 1
        time.sleep(0.01)  # a test program: stands in for the scheduler's wait


if __name__ == "__main__":
    main(sys.argv[1])
