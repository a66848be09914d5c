"""`ramp certs init|issue|list`: make the files SPEC 13's `server.tls` and clients' `--cert`,
`--key`, `--ca` (or `--identity`) name."""

from __future__ import annotations

import argparse
import datetime as dt
import sys
from pathlib import Path

ROLES = ("observer", "operator", "admin")


def add_certs_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("certs", help="make the robot's CA and certificates (mutual TLS)",
                       description="The robot's certificate authority (SPEC 13): `init` makes "
                       "the CA and the robot's server certificate, `issue` one client identity, "
                       "`list` what the directory holds.")
    certs = p.add_subparsers(dest="certs_command", required=True)
    init = certs.add_parser("init", help="make DIR/ca.crt, ca.key, robot.crt, robot.key")
    init.add_argument("dir", type=Path)
    init.add_argument("--host", action="append", required=True, metavar="NAME_OR_IP",
                      help="a name or address clients reach the robot by (repeat for each)")
    init.set_defaults(func=cmd_init)
    issue = certs.add_parser("issue", help="make DIR/NAME.crt, NAME.key and NAME.pem")
    issue.add_argument("dir", type=Path)
    issue.add_argument("name", help="the identity (certificate CN): 1-32 letters, digits, _, -")
    issue.add_argument("--role", choices=ROLES, default="operator",
                       help="the role to give it in access.identities (default operator)")
    issue.set_defaults(func=cmd_issue)
    lst = certs.add_parser("list", help="each certificate's CN, serial and expiry")
    lst.add_argument("dir", type=Path)
    lst.set_defaults(func=cmd_list)


def cmd_init(args: argparse.Namespace) -> int:
    from ramp.certs.authority import CertError, create_ca, issue_server

    try:
        create_ca(args.dir)
        crt, key = issue_server(args.dir, "robot", args.host)
    except CertError as exc:
        print(f"ramp certs: {exc}", file=sys.stderr)
        return 1
    print(f"ramp certs: CA {args.dir / 'ca.crt'} (keep {args.dir / 'ca.key'} off the robot "
          f"once clients are issued), robot certificate {crt} for {', '.join(args.host)}")
    print(f"ramp.yaml:\n  server:\n    tls: {{cert: {crt}, key: {key}, "
          f"client_ca: {args.dir / 'ca.crt'}}}")
    return 0


def cmd_issue(args: argparse.Namespace) -> int:
    from ramp.certs.authority import CertError, issue_client, list_certificates

    try:
        crt, key = issue_client(args.dir, args.name)
    except CertError as exc:
        print(f"ramp certs: {exc}", file=sys.stderr)
        return 1
    serial = next(c.serial for c in list_certificates(args.dir) if c.path == crt)
    print(f"ramp certs: {crt}, {key} and {args.dir / (args.name + '.pem')} "
          f"(serial {serial:#x}); add to ramp.yaml's access.identities:")
    print(f"    {args.name}: {args.role}")
    return 0


def cmd_list(args: argparse.Namespace) -> int:
    from ramp.certs.authority import list_certificates

    if not args.dir.is_dir():
        print(f"ramp certs: {args.dir} is not a directory", file=sys.stderr)
        return 1
    now = dt.datetime.now(dt.UTC)
    rows = list_certificates(args.dir)
    if not rows:
        print(f"ramp certs: no certificates in {args.dir}")
        return 0
    for c in rows:
        state = "EXPIRED" if c.not_after < now else f"expires {c.not_after:%Y-%m-%d}"
        print(f"{c.path.name:24} {c.kind:7} CN={c.common_name:24} serial={c.serial:#x} "
              f"{state}")
    return 0
