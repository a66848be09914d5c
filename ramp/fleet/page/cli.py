"""`ramp-fleet --broker HOST:PORT [--http-port P] [--console SERIAL=URL ...]`: the supervisor's
page (SPEC 14). It prints `ramp-fleet: page on http://127.0.0.1:P/` once serving."""

from __future__ import annotations

import argparse
import socket
import sys
from collections.abc import Sequence

HTTP_HOST = "127.0.0.1"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="ramp-fleet", description="The fleet supervisor's page: a tile per robot on the "
        "broker (VDA 5050), Stop all, pause/resume, missions.")
    p.add_argument("--broker", required=True, metavar="HOST:PORT", help="the MQTT broker")
    p.add_argument("--http-port", type=int, default=8090, metavar="P",
                   help="serve the page on 127.0.0.1:P (default 8090; 0 picks one)")
    p.add_argument("--console", action="append", default=[], metavar="SERIAL=URL",
                   help="a robot's operator console (ramp-teleop), linked from its tile")
    p.add_argument("--name", default="ramp-fleet", help="the MQTT client id (default ramp-fleet)")
    g = p.add_argument_group("TLS to the broker (ramp fleet init's supervisor certificate)")
    g.add_argument("--cert", metavar="FILE")
    g.add_argument("--key", metavar="FILE")
    g.add_argument("--ca", metavar="FILE")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from ramp.common.hostport import parse_hostport

    try:
        host, port = parse_hostport(args.broker, default_host="127.0.0.1")
        consoles = dict(_console(c) for c in args.console)
    except ValueError as exc:
        print(f"ramp-fleet: {exc}", file=sys.stderr)
        return 2
    tls = None
    if args.cert or args.key or args.ca:
        if not (args.cert and args.key and args.ca):
            print("ramp-fleet: --cert, --key and --ca go together", file=sys.stderr)
            return 2
        tls = {"cert": args.cert, "key": args.key, "ca": args.ca}
    try:
        import uvicorn  # noqa: F401 - the extras' check: said here, before anything starts

        from ramp.common.web import serve_app
        from ramp.fleet.page.app import create_app
        from ramp.fleet.page.supervisor import FleetSupervisor
    except ImportError as exc:
        print(f"ramp-fleet: {exc.name} is missing; install the extras: "
              "pip install 'ramp[fleet,teleop]'", file=sys.stderr)
        return 2
    try:
        sock = socket.create_server((HTTP_HOST, args.http_port))
    except OSError as exc:
        print(f"ramp-fleet: cannot serve on {HTTP_HOST}:{args.http_port}: {exc.strerror}",
              file=sys.stderr)
        return 2
    supervisor = FleetSupervisor(host, port, client_id=args.name, tls=tls, consoles=consoles)
    supervisor.start()
    try:
        serve_app(create_app(supervisor), sock, lambda: print(
            f"ramp-fleet: page on http://{HTTP_HOST}:{sock.getsockname()[1]}/ "
            f"(broker {host}:{port})", flush=True))
    finally:
        supervisor.close()
    return 0


def _console(text: str) -> tuple[str, str]:
    serial, sep, url = text.partition("=")
    if not sep or not serial or not url.startswith(("http://", "https://")):
        raise ValueError(f"--console {text!r}: expected SERIAL=http://HOST:PORT/")
    return serial, url


if __name__ == "__main__":
    sys.exit(main())
