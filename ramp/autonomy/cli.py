"""`ramp-autonomy`: the autonomy on the robot, and the check of its config (SPEC 6.3).

    ramp-autonomy --backend HOST:PORT [--config autonomy.yaml] [--start-box left|right]
                  [--foxglove-port P]
    ramp-autonomy check FILE

The first runs the RMC mission on the robot: the drivers `autonomy.yaml` names (the Hokuyo
at its address, the PhidgetSpatial IMU and the pan/tilt servo board), the wall clock, one
scheduler at 100 Hz, and the same executive and mission machine `ramp sim mission` runs in
the simulator (`ramp.autonomy.executive.Autonomy`), an MCP client of the backend at
`--backend` (default: the config's `backend:`). It logs one line per state change (and what
went wrong) to stderr, for journald. It ends when the mission is done (exit 0); a mission
waiting for its operator keeps running, since an operator can take over, put things right
and hand control back. SIGINT or SIGTERM stop the robot (`robot:robot.stop=()`) and end it
(exit 0). Exit 2 on a usage or config error, or when `--foxglove-port` cannot listen.

`--foxglove-port P` streams the autonomy's view live to Foxglove over its WebSocket protocol
(`ramp.autonomy.live`: the mission state, the estimated pose, the numbers, the scans and the
map, the channels `ramp sim mission --record` writes), on 127.0.0.1:P (0 picks a free port);
it prints `ramp-autonomy: foxglove live on ws://HOST:PORT` once listening. Only clients with
no Origin or a local one are served, and web pages of the origins given with
`--foxglove-origin ORIGIN` (repeatable, e.g. `https://app.foxglove.dev`).

`check` validates `autonomy.yaml` without touching any hardware, as `ramp check` validates
`ramp.yaml` (exit 2 when it has errors, as `ramp check` does; each error is
`file:line: key.path: what was expected`).
"""

from __future__ import annotations

import argparse
import logging
import signal
import ssl
import sys
from collections.abc import Sequence
from types import FrameType
from urllib.parse import urlsplit

from ramp.autonomy.config import AutonomyConfig, check_config, parse_address, tunable_notes
from ramp.autonomy.executive.autonomy import OWNER
from ramp.autonomy.live.foxglove_live import add_host_arguments as add_foxglove_host_arguments
from ramp.autonomy.live.foxglove_live import server_tls
from ramp.common.endpoint import add_tls_arguments, certificate_name, context_for, split_scheme
from ramp.common.hostport import format_hostport

DEFAULT_CONFIG = "autonomy.yaml"
STOP_FLUSH_S = 0.3  # after a signal: time for the stop to reach the backend


def summary(cfg: AutonomyConfig) -> list[str]:
    """A few lines saying what the file wires up."""
    g = cfg.gimbal
    return [
        f"backend {cfg.backend}",
        f"lidar {format_hostport(cfg.lidar.host, cfg.lidar.port)}",
        f"imu {cfg.imu.driver} serial {cfg.imu.serial} every {cfg.imu.data_interval_ms} ms",
        f"state estimation (IMU, AHRS, odometry) at {cfg.estimation_hz:g} Hz",
        f"gimbal {g.driver} serial {g.serial}: pan channel {g.pan.channel} "
        f"{g.pan.min_deg:g}..{g.pan.max_deg:g} deg, tilt channel {g.tilt.channel} "
        f"{g.tilt.min_deg:g}..{g.tilt.max_deg:g} deg",
        f"mission {len(cfg.mission)} tunables",
    ]


def web_origin(text: str) -> str:
    """`--foxglove-origin`: a web page's origin as a browser sends it (`https://HOST[:PORT]`,
    no path), scheme and host in lower case. Anything else never matched any page, so the
    operator's `--foxglove-origin '*'` or `https://app.foxglove.dev/` + a path was refused
    without a word."""
    try:
        parts = urlsplit(text.strip())
        port = parts.port  # ValueError when it is no port number
    except ValueError:
        parts, port = None, None
    if (parts is None or parts.scheme.lower() not in ("http", "https") or not parts.hostname
            or parts.username is not None or parts.path not in ("", "/") or parts.query
            or parts.fragment):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a web page's origin; expected http(s)://HOST[:PORT] with "
            "nothing after it, e.g. https://app.foxglove.dev")
    host = parts.hostname.lower()
    host = f"[{host}]" if ":" in host else host
    return f"{parts.scheme.lower()}://{host}" + (f":{port}" if port is not None else "")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ramp-autonomy",
        description="The RAMP autonomy: the RMC mission as an MCP client of the backend.",
        usage="ramp-autonomy --backend HOST:PORT [--config autonomy.yaml] "
              "[--start-box left|right] [--foxglove-port P]\n"
              "       ramp-autonomy check FILE")
    parser.add_argument("--backend", metavar="HOST:PORT",
                        help="the backend's MCP address (default: the config's backend); "
                             "mcps://HOST:PORT for mutual TLS with --cert/--key/--ca or "
                             "--identity (a certificate named autonomy)")
    add_tls_arguments(parser, "the backend")
    parser.add_argument("--config", default=DEFAULT_CONFIG, metavar="FILE",
                        help=f"the autonomy's config (default {DEFAULT_CONFIG})")
    parser.add_argument("--start-box", choices=("left", "right"), default=None,
                        help="the start box, when the team is told (default: the first "
                             "localization tries both)")
    parser.add_argument("--foxglove-port", type=int, default=None, metavar="P",
                        help="stream the autonomy's view live to Foxglove (WebSocket, "
                             "foxglove.websocket.v1) on 127.0.0.1:P; 0 picks a free port, "
                             "printed (needs the `foxglove` extra)")
    add_foxglove_host_arguments(parser)
    parser.add_argument("--command-port", type=int, default=None, metavar="P",
                        help="serve the command endpoint for the fleet agent on 127.0.0.1:P "
                             "(0 picks one; SPEC 14): the mission then waits for the "
                             "fleet's rmcMission")
    parser.add_argument("--foxglove-origin", action="append", default=[], metavar="ORIGIN",
                        type=web_origin,
                        help="a web page's origin allowed to open the live view besides "
                             "local ones (repeatable), e.g. https://app.foxglove.dev")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    check = sub.add_parser("check", help="validate an autonomy.yaml without touching hardware")
    check.add_argument("file", metavar="FILE", help="the autonomy config, e.g. autonomy.yaml")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "check":
        return cmd_check(args.file)
    if args.backend is None:
        parser.print_usage(sys.stderr)
        print("ramp-autonomy: error: give --backend HOST:PORT to run the mission, or "
              "`ramp-autonomy check FILE` to validate a config", file=sys.stderr)
        return 2
    return cmd_run(args)


def cmd_check(path: str) -> int:
    cfg, errors = check_config(path)
    if errors or cfg is None:
        for err in errors:
            print(err, file=sys.stderr)
        print(f"ramp-autonomy: {len(errors)} error(s) in {path}", file=sys.stderr)
        return 2
    print(f"{path}: ok")
    for line in summary(cfg):
        print(f"  {line}")
    for note in tunable_notes(cfg):
        print(f"  note: {note}")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    cfg, errors = check_config(args.config)
    if errors or cfg is None:
        for err in errors:
            print(err, file=sys.stderr)
        print(f"ramp-autonomy: {len(errors)} error(s) in {args.config}", file=sys.stderr)
        return 2
    try:
        tls, address = split_scheme(args.backend or "")
        backend = parse_address(address) if address else (cfg.backend_host, cfg.backend_port)
        backend_tls = context_for(tls, args)
        if backend_tls is not None:
            named = certificate_name(args.cert or args.identity)
            if named != OWNER:  # over TLS control is acquired under one's own identity
                raise ValueError(f"the autonomy acquires control as {OWNER!r}, so its "
                                 f"certificate's name must be {OWNER!r}, not {named!r}: "
                                 f"`ramp certs issue DIR {OWNER} --role operator`")
    except ValueError as exc:
        print(f"ramp-autonomy: --backend: {exc}", file=sys.stderr)
        return 2
    try:
        foxglove_tls = server_tls(args.foxglove_cert, args.foxglove_key)
    except ValueError as exc:
        print(f"ramp-autonomy: {exc}", file=sys.stderr)
        return 2
    port = args.foxglove_port
    if port is not None and not 0 <= port <= 65535:
        print(f"ramp-autonomy: --foxglove-port: expected 0-65535, got {port}", file=sys.stderr)
        return 2
    for kind, name in (("imu", cfg.imu.driver), ("gimbal", cfg.gimbal.driver)):
        if name == "sim":
            print(f"ramp-autonomy: {args.config}: {kind}.driver: 'sim' runs only in the "
                  "simulator (ramp sim mission); on the robot use phidget", file=sys.stderr)
            return 2
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    for note in tunable_notes(cfg):
        logging.getLogger("ramp.autonomy").warning("%s: %s", args.config, note)
    if args.command_port is not None and not 0 <= args.command_port <= 65535:
        print(f"ramp-autonomy: --command-port: expected 0-65535, got {args.command_port}",
              file=sys.stderr)
        return 2
    return run_on_robot(cfg, backend, start_box=args.start_box, foxglove_port=port,
                        foxglove_origins=args.foxglove_origin,
                        command_port=args.command_port, backend_tls=backend_tls,
                        foxglove_host=args.foxglove_host, foxglove_tls=foxglove_tls)


def run_on_robot(cfg: AutonomyConfig, backend: tuple[str, int], *,
                 start_box: str | None = None, foxglove_port: int | None = None,
                 foxglove_origins: Sequence[str] = (),
                 command_port: int | None = None,
                 backend_tls: ssl.SSLContext | None = None,
                 foxglove_host: str = "127.0.0.1",
                 foxglove_tls: ssl.SSLContext | None = None) -> int:
    """The mission on real hardware, on the wall clock, until done or a signal."""
    from ramp.autonomy.executive.autonomy import Autonomy
    from ramp.autonomy.hal import driver_class
    from ramp.autonomy.hal.hokuyo import HokuyoLidar
    from ramp.autonomy.live import FoxgloveLive, LiveViewError
    from ramp.autonomy.live.view import LATCHED, VIEW_HZ, AutonomyView
    from ramp.autonomy.perception.stack import Perception
    from ramp.clock import MonotonicClock
    from ramp.errors import DeviceError
    from ramp.scheduler import Scheduler

    log = logging.getLogger("ramp.autonomy")
    clock = MonotonicClock()
    scheduler = Scheduler(clock, 100.0)
    now = clock.now()
    live = None
    if foxglove_port is not None:  # before any device: a port in use changes nothing
        try:
            live = FoxgloveLive(port=foxglove_port, name="ramp-autonomy", latched=LATCHED,
                                origins=foxglove_origins, host=foxglove_host,
                                ssl_context=foxglove_tls)
            live.start(now)
        except LiveViewError as exc:
            print(f"ramp-autonomy: --foxglove-port: {exc}", file=sys.stderr)
            return 2
        print(f"ramp-autonomy: foxglove live on {live.url}", flush=True)
    lidar = HokuyoLidar(format_hostport(cfg.lidar.host, cfg.lidar.port), clock=clock,
                        loop=scheduler)
    imu = driver_class("imu", cfg.imu.driver)(cfg.imu)
    pan_tilt = driver_class("gimbal", cfg.gimbal.driver)(cfg.gimbal)
    perception = Perception(cfg, lidar, imu, pan_tilt, now=now)
    perception.add_tasks(scheduler)
    for device in (imu, pan_tilt):
        try:
            device.open(now)
        except DeviceError as exc:  # the vendor library is missing: say so, and go on
            device.fault = exc     # without it; the mission waits for its sensors (naming
            log.error("%s", exc)   # this one) and then for an operator
    lidar.start()  # scans on demand: the mission asks for them (Perception.start's steps)
    autonomy = Autonomy(scheduler, perception, cfg, backend, start_box=start_box,
                        backend_tls=backend_tls)
    view = None
    if live is not None:  # after the mission's task, so each sample sees that tick's work
        view = AutonomyView.watching(live, autonomy)
        scheduler.add_task("autonomy.view", VIEW_HZ, view.tick)
    commands = None
    if command_port is not None:  # the fleet agent's way in (ramp/autonomy/command.py)
        from ramp.autonomy.command import CommandEndpoint

        tracker = autonomy.kit.tracker
        try:
            commands = CommandEndpoint(autonomy.mission, pose=tracker.estimate,
                                       confidence=lambda: tracker.confidence, now=clock.now,
                                       port=command_port, kit=autonomy.kit)
        except OSError as exc:
            print(f"ramp-autonomy: --command-port: {exc}", file=sys.stderr)
            autonomy.close()
            perception.close()
            return 2
        scheduler.add_task("autonomy.commands", 20.0, commands.tick)
        print("ramp-autonomy: commands on {}:{} (the mission waits for rmcMission)".format(
            *commands.address), flush=True)
    stopping: list[str] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stopping.append(signal.Signals(signum).name)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    log.info("ramp-autonomy: mission of %g s against the backend at %s:%d",
             autonomy.mission.config.duration_s, *backend)
    autonomy.start(clock.now())
    try:
        scheduler.run(lambda: bool(stopping) or autonomy.mission.over)
        if stopping:
            log.warning("ramp-autonomy: %s: stopping the robot", stopping[0])
            if autonomy.mission.has_control:
                autonomy.robot.stop_all()
            end = clock.now() + STOP_FLUSH_S
            scheduler.run(lambda: clock.now() >= end)
    finally:
        if commands is not None:
            commands.close()
        if view is not None:
            view.close()
        autonomy.close()
        perception.close()
        if live is not None:
            live.close()
    log.info("ramp-autonomy: mission %s (%s)", autonomy.mission.outcome,
             autonomy.mission.state)
    return 0


if __name__ == "__main__":
    sys.exit(main())
