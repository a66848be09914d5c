"""`ramp fleet ...`: the fleet's subcommands of `ramp` (SPEC 14).

`FLEET_COMMANDS` maps a name to the function that adds its parser, so each subcommand lives
in its own module and registers here with one line.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    SubParsers = argparse._SubParsersAction[argparse.ArgumentParser]


def add_init(sub: SubParsers) -> None:
    p = sub.add_parser(
        "init", help="write a TLS Mosquitto set-up: certificates, mosquitto.conf and its ACL",
        description="Write DIR/ca.crt, DIR/broker.crt, one certificate per robot and "
                    "supervisor (CN = its name), DIR/mosquitto.conf (a TLS listener that "
                    "requires a client certificate, its CN the user name) and DIR/acl (a "
                    "robot writes only its own connection/state/visualization/factsheet and "
                    "reads only its own order/instantActions; supervisors write "
                    "order/instantActions and read all).")
    p.add_argument("dir", type=Path)
    p.add_argument("--robots", nargs="+", default=[], metavar="NAME",
                   help="the robots' serials (their fleet.serial)")
    p.add_argument("--supervisors", nargs="+", default=[], metavar="NAME",
                   help="the supervisors' names (ramp-fleet, a VDA 5050 master)")
    p.add_argument("--host", nargs="+", default=["localhost", "127.0.0.1"],
                   metavar="NAME_OR_IP", help="the broker's names and addresses, as robots "
                   "reach it (default localhost 127.0.0.1)")
    p.add_argument("--port", type=int, default=8883, help="the TLS listener (default 8883)")
    p.add_argument("--manufacturer", default="RAMP",
                   help="the robots' fleet.manufacturer (default RAMP)")
    p.set_defaults(func=cmd_init)


def cmd_init(args: argparse.Namespace) -> int:
    from ramp.certs.authority import CertError
    from ramp.fleet.init import check_names, write_fleet

    problems = check_names(args.robots, args.supervisors)
    if not 0 < args.port < 65536:
        problems.append(f"--port {args.port} is not a port 1-65535")
    if problems:
        for problem in problems:
            print(f"ramp fleet init: {problem}", file=sys.stderr)
        return 2
    try:
        files = write_fleet(args.dir, args.robots, args.supervisors, hosts=args.host,
                            port=args.port, manufacturer=args.manufacturer)
    except (OSError, ValueError, RuntimeError, CertError) as exc:
        print(f"ramp fleet init: {exc}", file=sys.stderr)
        return 1
    d = files.directory
    print(f"ramp fleet init: wrote {files.conf} and {files.acl}; run the broker with "
          f"mosquitto -c {files.conf}")
    for robot in args.robots:
        print(f"  robot {robot}: in its ramp.yaml, fleet: {{manufacturer: {args.manufacturer}, "
              f"serial: {robot}, broker: {args.host[0]}:{args.port}, tls: {{ca: {d}/ca.crt, "
              f"cert: {d}/{robot}.crt, key: {d}/{robot}.key}}}}")
    for sup in args.supervisors:
        print(f"  supervisor {sup}: --cert {d}/{sup}.crt --key {d}/{sup}.key --ca {d}/ca.crt")
    return 0


def add_sim(sub: SubParsers) -> None:
    from ramp.fleet.sim import add_sim as add

    add(sub)


FLEET_COMMANDS: dict[str, Callable[[SubParsers], None]] = {  # noqa: F821
    "init": add_init, "sim": add_sim}


def add_fleet_parser(sub: SubParsers) -> None:
    """Add `fleet` and its subcommands to `ramp`'s subparsers."""
    fleet = sub.add_parser("fleet", help="the fleet over MQTT (VDA 5050): init ...",
                           description="Many robots over MQTT, speaking VDA 5050 (SPEC 14).")
    fleet_sub = fleet.add_subparsers(dest="fleet_command", required=True, metavar="COMMAND")
    for add in FLEET_COMMANDS.values():
        add(fleet_sub)
