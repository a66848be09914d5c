"""`ramp sim …`: the simulation subcommands, registered on `ramp`'s own parser.

`ramp.cli` calls `add_sim_parser(subparsers)` once; each subcommand adds its parser in
`SIM_COMMANDS` (name -> function), so a new one is one entry here, not an edit of `ramp.cli`.
Nothing heavy is imported until a subcommand runs (numpy, the emulators, matplotlib), so
`ramp run` and `ramp check` start as fast as before.

    ramp sim lidar (--world FILE | --seed N) --at X,Y,YAW [--tilt DEG] [--pan DEG]
                   [--plot FILE.png] [--json]

Exit status: 0 done, 2 usage or world-file error (each error on stderr as
`file:line: key.path: what was expected`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from typing import Any


class UsageError(Exception):
    """A bad argument, reported as `ramp sim: OPTION: what was expected` with exit 2."""


def add_lidar_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "lidar", help="draw one emulated LIDAR scan over the arena map",
        description="Ray-cast one Hokuyo UTM-30LX-EW scan in the simulated arena from a given "
                    "robot pose and gimbal angle, and draw it (or print it).")
    where = p.add_argument_group("world (the SPEC 6.1 arena)")
    where.add_argument("--world", metavar="FILE",
                       help="world file (YAML: start, rocks, craters); default: a seeded layout")
    where.add_argument("--seed", type=int, default=0, metavar="N",
                       help="seed of the layout (without --world), of the ground's "
                            "undulation and of the range noise (default 0)")
    p.add_argument("--at", required=True, metavar="X,Y,YAW",
                   help="robot pose: footprint centre in metres, yaw in degrees "
                        "counter-clockwise from +x (e.g. 1.2,1.94,0)")
    p.add_argument("--tilt", type=float, default=0.0, metavar="DEG",
                   help="gimbal tilt, positive tips the scan plane down (default 0)")
    p.add_argument("--pan", type=float, default=0.0, metavar="DEG",
                   help="gimbal pan, counter-clockwise positive (default 0)")
    p.add_argument("--plot", metavar="FILE.png", help="draw the scan over the arena map")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object (the pose, the counts, every range in mm)")
    p.set_defaults(func=cmd_lidar)


def add_campaign_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from ramp.simulation.campaign import add_parser

    add_parser(sub)


#: Every `ramp sim` subcommand: name -> function adding its parser.
SIM_COMMANDS: dict[str, Callable[[argparse._SubParsersAction[argparse.ArgumentParser]],
                                 None]] = {
    "lidar": add_lidar_parser,
    "campaign": add_campaign_parser,
}


def add_sim_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add `sim` and its subcommands to `ramp`'s subparsers."""
    sim = sub.add_parser("sim", help="simulation tools: the arena, its sensors, missions",
                         description="Simulation tools on the emulated MARTE and RMC arena.")
    sim_sub = sim.add_subparsers(dest="sim_command", required=True, metavar="COMMAND")
    for add in SIM_COMMANDS.values():
        add(sim_sub)


def parse_pose(text: str) -> tuple[float, float, float]:
    """`X,Y,YAW` -> floats; raises UsageError saying what was expected."""
    parts = text.split(",")
    try:
        values = [float(v) for v in parts]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise UsageError(f"--at: expected X,Y,YAW (metres, metres, degrees), got {text!r}")
    return values[0], values[1], values[2]


def cmd_lidar(args: argparse.Namespace) -> int:
    try:
        return _lidar(args)
    except UsageError as exc:
        print(f"ramp sim lidar: {exc}", file=sys.stderr)
        return 2


def _lidar(args: argparse.Namespace) -> int:
    from firmware_like.arena import random_layout, rule_problems
    from firmware_like.arena_params import HIT_NAMES
    from firmware_like.lidar_view import LidarView
    from firmware_like.marte import MarteWorld
    from firmware_like.world_file import WorldFileError, load_world

    x, y, yaw = parse_pose(args.at)
    for name in ("tilt", "pan"):
        if not math.isfinite(getattr(args, name)):
            raise UsageError(f"--{name}: expected an angle in degrees")
    if args.world:
        try:
            layout = load_world(args.world)
        except WorldFileError as exc:
            for err in exc.errors:
                print(err, file=sys.stderr)
            return 2
    else:
        layout = random_layout(args.seed)
    world = MarteWorld(seed=args.seed, layout=layout)
    try:
        world.place(x, y, yaw)
    except ValueError as exc:
        raise UsageError(f"--at: {exc}") from exc
    view = LidarView.of(world)
    pan, tilt = math.radians(args.pan), math.radians(args.tilt)
    scan = view.scan(view.pose_of_world(pan, tilt))
    counts = {name: int((scan.kinds == k).sum()) for k, name in enumerate(HIT_NAMES)}
    if args.plot:
        try:
            from ramp.simulation.lidar_plot import draw_scan
        except ImportError as exc:
            raise UsageError("--plot needs matplotlib: pip install 'ramp[plot]'") from exc
        draw_scan(world, scan, view.angles, args.plot, pan_deg=args.pan, tilt_deg=args.tilt)
    notes = rule_problems(layout, args.seed) if args.world else []
    if args.json:
        doc: dict[str, Any] = {
            "world": layout.source, "seed": args.seed,
            "pose": {"x": world.x, "y": world.y, "yaw": world.heading_deg},
            "chassis": {"z": world.z, "roll": math.degrees(world.roll),
                        "pitch": math.degrees(world.pitch)},
            "lidar": {"origin": [round(float(v), 4) for v in scan.pose.origin],
                      "pan": args.pan, "tilt": args.tilt},
            "rocks": [vars(r) for r in layout.rocks],
            "craters": [vars(c) for c in layout.craters],
            "hits": counts, "rule_notes": notes, "plot": args.plot,
            "ranges_mm": [int(v) for v in scan.mm],
        }
        print(json.dumps(doc))
        return 0
    front = int(scan.mm[view.params.front_step])
    print(f"{layout.source}: scan from x {world.x:.2f} y {world.y:.2f} yaw "
          f"{world.heading_deg:.1f} deg, pan {args.pan:g} tilt {args.tilt:g} deg "
          f"(chassis pitch {math.degrees(world.pitch):.1f}, roll "
          f"{math.degrees(world.roll):.1f} deg)")
    print("  " + ", ".join(f"{n} {c}" for n, c in counts.items() if c) +
          f"; straight ahead {front} mm")
    for note in notes:
        print(f"  note: departs from the competition rules: {note}")
    if args.plot:
        print(f"  plot written to {args.plot}")
    return 0
