"""`ramp sim …`: the simulation subcommands, registered on `ramp`'s own parser.

`ramp.cli` calls `add_sim_parser(subparsers)` once; each subcommand adds its parser in
`SIM_COMMANDS` (name -> function), so a new one is one entry here, not an edit of `ramp.cli`.
Nothing heavy is imported until a subcommand runs (numpy, the emulators, matplotlib), so
`ramp run` and `ramp check` start as fast as before.

    ramp sim lidar (--world FILE | --seed N) --at X,Y,YAW [--tilt DEG] [--pan DEG]
                   [--via-scip] [--plot FILE.png] [--json]
    ramp sim perceive [--world FILE | --seed N] --at X,Y,YAW [--hint left|right]
                      [--fault none|gyro-drift|imu-shift] [--config FILE] [--json]
                      [--plot FILE.png]
    ramp sim mission [--seed N] [--start-box left|right] [--heading 0|90|180|270]
                     [--world FILE] [--fault ...] [--duration 600] [--json] [--trace FILE]
                     [--plot FILE.png] [--record FILE.mcap] [--realtime [--port P]]
                     (ramp/simulation/mission_cli.py)

`ramp sim perceive` needs the autonomy package (`ramp/autonomy/`); it is imported only when
that subcommand runs, so the others work without it.

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

from ramp.common.outputs import figure_file, plot_unavailable
from ramp.simulation.arguments import MAX_YAW_DEG, ArgumentError, check_seed, check_yaw


class UsageError(Exception):
    """A bad argument, reported as `ramp sim: OPTION: what was expected` with exit 2."""


def _check_plot(plot: str | None) -> None:
    """A picture that could not be drawn is refused before the work, not after it."""
    problem = plot_unavailable(plot)
    if problem is not None:
        raise UsageError(problem)


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
    p.add_argument("--via-scip", action="store_true",
                   help="take the scan through the real path: the Hokuyo emulator serving "
                        "SCIP 2.0 on loopback TCP to the autonomy's LIDAR driver (needs the "
                        "autonomy package); the ranges are the same")
    p.add_argument("--plot", type=figure_file, metavar="FILE.png",
                   help="draw the scan over the arena map")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object (the pose, the counts, every range in mm)")
    p.set_defaults(func=cmd_lidar)


def add_campaign_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from ramp.simulation.campaign import add_parser

    add_parser(sub)


def add_mission_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from ramp.simulation.mission_cli import add_mission_parser as add

    add(sub)


def add_perceive_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "perceive", help="localize and detect obstacles from one pose, on the emulated sensors",
        description="Place the robot, let the AHRS settle and the gimbal level the LIDAR, "
                    "localize from level scans, sweep the LIDAR's tilt stop and go for a 3D "
                    "scan, check level against the scan and the floor (re-levelling and "
                    "localizing again when the IMU has moved) and detect rocks and craters: "
                    "the real drivers on the emulators, on a virtual clock. Prints the "
                    "estimated pose with its confidence (or LOST and why) and the obstacles "
                    "found.")
    where = p.add_argument_group("world (the SPEC 6.1 arena)")
    where.add_argument("--world", metavar="FILE",
                       help="world file (YAML: start, rocks, craters); default: a seeded layout")
    where.add_argument("--seed", type=int, default=0, metavar="N",
                       help="seed of the layout (without --world), of the ground's "
                            "undulation, the sensors' noise and the IMU's fault (default 0)")
    p.add_argument("--at", required=True, metavar="X,Y,YAW",
                   help="robot pose: footprint centre in metres, yaw in degrees "
                        "counter-clockwise from +x (e.g. 0.8,2.9,0)")
    p.add_argument("--hint", choices=("left", "right"),
                   help="the start box the robot is known to be in (initial localization); "
                        "without it the AHRS starts within 20 deg of the true yaw")
    p.add_argument("--fault", choices=("none", "gyro-drift", "imu-shift"), default="none",
                   help="IMU fault to inject (SPEC 6.2; default none)")
    p.add_argument("--config", metavar="FILE",
                   help="the autonomy's config (default: the repository's autonomy.yaml)")
    p.add_argument("--plot", type=figure_file, metavar="FILE.png",
                   help="draw the localization and the obstacle map")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object: pose (or null when lost), lost, obstacles, "
                        "true_pose and the details")
    p.set_defaults(func=cmd_perceive)


#: Every `ramp sim` subcommand: name -> function adding its parser.
SIM_COMMANDS: dict[str, Callable[[argparse._SubParsersAction[argparse.ArgumentParser]],
                                 None]] = {
    "lidar": add_lidar_parser,
    "campaign": add_campaign_parser,
    "perceive": add_perceive_parser,
    "mission": add_mission_parser,
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
    checked(check_yaw, values[2], "--at")
    return values[0], values[1], values[2]


def checked(check: Callable[..., None], *args: Any) -> None:
    """Run one of `ramp.simulation.arguments`' checks; its complaint is a usage error."""
    try:
        check(*args)
    except ArgumentError as exc:
        raise UsageError(str(exc)) from exc


def cmd_lidar(args: argparse.Namespace) -> int:
    try:
        return _lidar(args)
    except UsageError as exc:
        print(f"ramp sim lidar: {exc}", file=sys.stderr)
        return 2


def _lidar(args: argparse.Namespace) -> int:
    _check_plot(args.plot)
    from firmware_like.arena import random_layout, rule_problems
    from firmware_like.arena_params import HIT_NAMES
    from firmware_like.lidar_view import LidarView
    from firmware_like.marte import MarteWorld
    from firmware_like.world_file import WorldFileError, load_world

    x, y, yaw = parse_pose(args.at)
    checked(check_seed, args.seed)
    for name in ("tilt", "pan"):
        deg = getattr(args, name)
        if not (math.isfinite(deg) and -MAX_YAW_DEG <= deg <= MAX_YAW_DEG):
            raise UsageError(f"--{name}: expected an angle in degrees, -{MAX_YAW_DEG:g} to "
                             f"{MAX_YAW_DEG:g}, got {deg:g}")
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
    if args.via_scip:
        scan = _through_scip(world, scan, pan, tilt)
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
            "via_scip": bool(args.via_scip),
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


def _through_scip(world: Any, direct: Any, pan: float, tilt: float) -> Any:
    """The same scan, taken by the autonomy's Hokuyo driver from the emulator over TCP.

    A fresh view with the same seed draws the same noise, so the emulator's first scan is
    `direct`'s; the driver's ranges replace the direct ones (a mismatch is an error: the
    bytes lost something)."""
    from dataclasses import replace

    import numpy as np

    from firmware_like.hokuyo import HokuyoEmulator
    from firmware_like.lidar_view import LidarView
    from ramp.clock import VirtualClock
    from ramp.scheduler import Scheduler

    try:
        from ramp.autonomy.hal.hokuyo import HokuyoLidar
    except ImportError as exc:
        raise UsageError("--via-scip needs the autonomy package (ramp/autonomy)") from exc
    view = LidarView.of(world)
    pose = view.pose_of_world(pan, tilt)
    clock = VirtualClock()
    loop = Scheduler(clock, 100.0)
    emulator = HokuyoEmulator(clock, lambda t: view.scan(pose).mm, port=0)
    emulator.attach(loop)
    lidar = HokuyoLidar(emulator.url, clock=clock, loop=loop)
    loop.add_task("emulator", 100.0, lambda now, dt: emulator.service(now))
    loop.add_task("lidar", 100.0, lidar.tick)
    try:
        lidar.start()
        asked = False

        def got() -> bool:
            nonlocal asked
            if not asked:
                asked = lidar.request_scan()
            return lidar.latest is not None

        end = clock.now() + 3.0
        loop.run(lambda: got() or clock.now() >= end)
        scan = lidar.latest
        if scan is None:
            raise UsageError(f"--via-scip: no scan from the emulator ({lidar.state}: "
                             f"{lidar.fault})")
    finally:
        lidar.stop()
        emulator.close()
    mm = np.asarray(scan.raw, dtype=np.int64)
    if not np.array_equal(mm, direct.mm):
        raise RuntimeError("the scan read over SCIP differs from the one the emulator cast")
    return replace(direct, mm=mm, ranges=np.where(scan.valid, scan.ranges, np.nan))


def cmd_perceive(args: argparse.Namespace) -> int:
    try:
        return _perceive(args)
    except UsageError as exc:
        print(f"ramp sim perceive: {exc}", file=sys.stderr)
        return 2


def _perceive(args: argparse.Namespace) -> int:
    import logging

    _check_plot(args.plot)

    from firmware_like.arena import random_layout
    from firmware_like.marte import MarteWorld
    from firmware_like.world_file import WorldFileError, load_world

    try:
        from ramp.errors import ConfigErrors
        from ramp.simulation.perceive import PerceiveError, perceive
        from ramp.simulation.rig import load_autonomy_config
    except ImportError as exc:
        print(f"ramp sim perceive: needs the autonomy package: {exc}", file=sys.stderr)
        return 1
    x, y, yaw = parse_pose(args.at)
    checked(check_seed, args.seed)
    seed = args.seed
    if args.world:
        try:
            layout = load_world(args.world)
        except WorldFileError as exc:
            for err in exc.errors:
                print(err, file=sys.stderr)
            return 2
    else:
        layout = random_layout(seed)
    try:
        config = load_autonomy_config(args.config)
    except ConfigErrors as exc:
        for problem in exc.errors:
            print(problem, file=sys.stderr)
        return 2
    world = MarteWorld(seed=seed, layout=layout)
    try:
        world.place(x, y, yaw)
    except ValueError as exc:
        raise UsageError(f"--at: {exc}") from exc
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")
    try:
        result = perceive(world, config, seed=seed, fault=args.fault, hint=args.hint)
    except PerceiveError as exc:
        print(f"ramp sim perceive: {exc}", file=sys.stderr)
        return 1
    if args.plot:
        try:
            from ramp.simulation.perceive_plot import draw_perception
        except ImportError as exc:
            raise UsageError("--plot needs matplotlib: pip install 'ramp[plot]'") from exc
        where = layout.source if layout.source == f"seed {seed}" else (
            f"{layout.source}, seed {seed}")
        draw_perception(world, result, args.plot, title=(
            f"{where}: robot at x {x:g} y {y:g} yaw {yaw:g}°, "
            f"hint {args.hint or 'none'}, fault {args.fault}"))
    doc = result.to_json(world=layout.source, seed=seed, fault=args.fault, hint=args.hint,
                         plot=args.plot)
    if args.json:
        print(json.dumps(doc))
        return 0
    for line in describe_perception(doc):
        print(line)
    return 0


def describe_perception(doc: dict[str, Any]) -> list[str]:
    """The result in a few lines a person reads."""
    def pose(p: dict[str, Any]) -> str:
        return f"x {p['x']:.3f} y {p['y']:.3f} yaw {p['yaw']:.1f} deg"

    where = doc["world"] if doc["world"] == f"seed {doc['seed']}" else (
        f"{doc['world']}: seed {doc['seed']}")
    out = [f"{where}, fault {doc['fault']}, hint {doc['hint'] or 'none'}"]
    out.append(f"  true pose:      {pose(doc['true_pose'])}")
    if doc["moved_off"]:
        out.append(f"  note: {doc['moved_off']}")
    if doc["lost"] or doc["pose"] is None:
        out.append(f"  estimated pose: LOST ({doc['reason'] or 'no reason given'})")
    else:
        out.append(f"  estimated pose: {pose(doc['pose'])} (confidence "
                   f"{doc['pose']['confidence']:.2f})")
    if len(doc["candidates"]) > 1:
        out.append("  candidates:     " + "; ".join(pose(c) for c in doc["candidates"]))
    for fix in doc["level_fixes"]:
        out.append(f"  re-levelled from the {fix['from']} at {fix['t']:.1f} s: the IMU's level "
                   f"was {fix['deg']:.1f} deg off")
    if doc["retakes"]:
        out.append(f"  scanned and localized again {doc['retakes']} time(s): the AHRS "
                   "corrected its IMU mount meanwhile")
    if doc["imu"]["suspect"]:
        out.append(f"  IMU suspect: {doc['imu']['reason']}")
    out.append(f"  obstacles ({len(doc['obstacles'])} detected, "
               f"{len(doc['true_obstacles'])} in the world):")
    for o in doc["obstacles"]:
        out.append(f"    {o['kind']:6s} at x {o['x']:.2f} y {o['y']:.2f}, d {o['d']:.2f} m")
    if doc["sweep_note"]:
        out.append(f"  sweep: {doc['sweep_note']}")
    side = f" (+{doc['side_scans']} to the sides)" if doc["side_scans"] else ""
    out.append(f"  {doc['scans']} level scans, {doc['sweep_scans']} sweep scans{side}; "
               f"{doc['sim_time_s']:.1f} s simulated in {doc['wall_time_s']:.1f} s")
    if doc.get("plot"):
        out.append(f"  plot written to {doc['plot']}")
    return out
