"""`ramp-autonomy`: the autonomy's command line.

For now it validates `autonomy.yaml` (`ramp-autonomy check FILE`) without touching any
hardware, the way `ramp check` validates `ramp.yaml`. Running the mission on the robot
(`ramp-autonomy --backend HOST:PORT [--config autonomy.yaml]`, SPEC 6.3) comes with the
mission itself.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from ramp.autonomy.config import AutonomyConfig, check_config


def summary(cfg: AutonomyConfig) -> list[str]:
    """A few lines saying what the file wires up."""
    g = cfg.gimbal
    return [
        f"backend {cfg.backend}",
        f"lidar {cfg.lidar.host}:{cfg.lidar.port}",
        f"imu {cfg.imu.driver} serial {cfg.imu.serial} every {cfg.imu.data_interval_ms} ms",
        f"gimbal {g.driver} serial {g.serial}: pan channel {g.pan.channel} "
        f"{g.pan.min_deg:g}..{g.pan.max_deg:g} deg, tilt channel {g.tilt.channel} "
        f"{g.tilt.min_deg:g}..{g.tilt.max_deg:g} deg",
        f"mission {len(cfg.mission)} tunables",
    ]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="ramp-autonomy", description="The RAMP autonomy (an MCP client of the backend).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    check = sub.add_parser("check", help="validate an autonomy.yaml without touching hardware")
    check.add_argument("file", metavar="FILE", help="the autonomy config, e.g. autonomy.yaml")
    args = parser.parse_args(argv)
    if args.command != "check":
        parser.print_usage(sys.stderr)
        print("ramp-autonomy: error: only `ramp-autonomy check FILE` is available in this "
              "version", file=sys.stderr)
        return 2
    cfg, errors = check_config(args.file)
    if errors or cfg is None:
        for err in errors:
            print(err, file=sys.stderr)
        print(f"ramp-autonomy: {len(errors)} error(s) in {args.file}", file=sys.stderr)
        return 1
    print(f"{args.file}: ok")
    for line in summary(cfg):
        print(f"  {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
