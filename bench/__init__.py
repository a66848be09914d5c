"""RAMP benchmark suite: `python -m bench [--quick] [--only NAME[,NAME]] [--out FILE]`.

Every figure is measured on real processes and real sockets on this machine, beside a
baseline measured in the same run (a bare Python loop or server doing the minimum), so a
slow machine or a busy neighbour shows up in both and the ratio stays meaningful. Nothing
here asserts a threshold: the suite reports, people judge.
"""

from __future__ import annotations

from importlib.util import find_spec

#: Sections that measure the removable autonomy package: present only when it is.
AUTONOMY_SECTIONS: tuple[str, ...] = (
    (
        "autonomy_sensors",
        "lidar_codec",
        "planner",
        "rig",
        "obstacles",
        "localizer",
        "perception",
        "mission",
        "console_bandwidth",
        "realtime",
    )
    if find_spec("ramp.autonomy") is not None else ())

#: Benchmark names, in the order they run.
SECTIONS = ("tick", "round_trip", "tls", "interlocks", "command_to_wire", "watchdog_to_wire",
            "startup", "recorder", "fleet",
            "arena", *AUTONOMY_SECTIONS)
