"""`ramp-teleop --backend HOST:PORT [--autonomy HOST:PORT] [--http-port P] [--name operator]
[--profile NAME]`.

Serves the operator console on 127.0.0.1 (the page drives a robot: it is not offered to the
network) and prints `ramp-teleop: open http://127.0.0.1:PORT/` once it is serving.
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
from collections.abc import Sequence

from ramp.common.endpoint import add_tls_arguments, certificate_name, context_for, split_scheme
from ramp.common.web import serve_app
from ramp.mcp.client import parse_address
from ramp.teleop.profile import DEFAULT_PROFILE, ProfileError, ProfileLibrary

HTTP_HOST = "127.0.0.1"
_NAME = re.compile(r"[A-Za-z0-9_-]{1,32}\Z")
EXIT_OK, EXIT_USAGE = 0, 2


def _name(text: str) -> str:
    if not _NAME.match(text) or text == "none":
        raise argparse.ArgumentTypeError(
            f"{text!r}: 1-32 letters, digits, '_' or '-' ('none' is reserved)")
    return text


def _battery(text: str) -> tuple[float, float]:
    try:
        empty, full = (float(x) for x in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected EMPTY:FULL volts, e.g. 17:21") from None
    if not 0 <= empty < full:
        raise argparse.ArgumentTypeError(f"{text!r}: expected 0 <= EMPTY < FULL")
    return empty, full


MIN_POLL_HZ = 0.1  # one poll in 10 s: the slowest status the console still calls live


def _rate(text: str) -> float:
    try:
        hz = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    # Below 0.1 Hz (1e-300 was accepted) the page's status would go stale without a word.
    if not MIN_POLL_HZ <= hz <= 100:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {MIN_POLL_HZ:g} <= HZ <= 100")
    return hz


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="ramp-teleop",
        description="Operator console in the browser for a RAMP robot: live status, every "
                    "function, a gamepad with a dead-man button, and a STOP that always works.")
    p.add_argument("--backend", default="127.0.0.1:5577", metavar="HOST:PORT",
                   help="the robot's MCP address (default 127.0.0.1:5577); mcps://HOST:PORT "
                        "for mutual TLS with --cert/--key/--ca or --identity")
    p.add_argument("--autonomy", default=None, metavar="HOST:PORT",
                   help="the autonomy's live view (ramp-autonomy --foxglove-port, ramp sim "
                        "mission --foxglove-port): shows its state, map and alerts; without "
                        "it, or while it is unreachable, the console works as before")
    p.add_argument("--http-port", type=int, default=8080, metavar="P",
                   help="port of the page on 127.0.0.1 (default 8080; 0 picks a free one)")
    p.add_argument("--name", type=_name, default=None,
                   help="who takes control with 'Take control' (default operator; over "
                        "mcps:// the certificate's name, the only one the robot accepts)")
    p.add_argument("--profile", default=DEFAULT_PROFILE, metavar="NAME",
                   help="gamepad profile: a file NAME.yaml among the built-in profiles or in "
                        "$XDG_CONFIG_HOME/ramp/profiles (default: default)")
    p.add_argument("--poll-hz", type=_rate, default=10.0, metavar="HZ",
                   help="status poll rate (default 10)")
    p.add_argument("--battery", type=_battery, default=(17.0, 21.0), metavar="EMPTY:FULL",
                   help="volts of an empty and a full battery for the gauge (default 17:21, "
                        "MARTE's 5S LiPo rail)")
    p.add_argument("-v", "--verbose", action="store_true", help="log link changes")
    add_tls_arguments(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        tls, backend = split_scheme(args.backend)
        host, port = parse_address(backend)
        ssl_context = context_for(tls, args)
    except ValueError as exc:
        print(f"ramp-teleop: --backend: {exc}", file=sys.stderr)
        return EXIT_USAGE
    name = args.name or "operator"
    if ssl_context is not None:  # over TLS control is acquired under one's own identity
        identity = certificate_name(args.cert or args.identity)
        if args.name is None and identity:
            name = identity
        elif identity and args.name != identity:
            print(f"ramp-teleop: --name {args.name}: the robot accepts control only under "
                  f"this console's identity, {identity} (its certificate's name)",
                  file=sys.stderr)
            return EXIT_USAGE
    autonomy = None
    if args.autonomy is not None:
        try:
            autonomy = parse_address(args.autonomy)
        except ValueError as exc:
            print(f"ramp-teleop: --autonomy: {exc}", file=sys.stderr)
            return EXIT_USAGE
    if not 0 <= args.http_port <= 65535:
        print("ramp-teleop: --http-port must be 0-65535", file=sys.stderr)
        return EXIT_USAGE
    library = ProfileLibrary()
    try:
        profile = library.load(args.profile)
    except ProfileError as exc:
        print(f"ramp-teleop: {exc}", file=sys.stderr)
        return EXIT_USAGE
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        import uvicorn  # noqa: F401 - the extra's check: said here, before anything starts

        from ramp.teleop.app import create_app
        from ramp.teleop.console import Console
    except ImportError as exc:
        print(f"ramp-teleop: {exc.name} is missing; install the console's extra: "
              "pip install 'ramp[teleop]'", file=sys.stderr)
        return EXIT_USAGE
    from ramp.teleop.listen import listen, raise_fd_limit

    raise_fd_limit()
    try:
        sock = listen(HTTP_HOST, args.http_port)
    except OSError as exc:
        print(f"ramp-teleop: cannot serve on {HTTP_HOST}:{args.http_port}: {exc.strerror}",
              file=sys.stderr)
        return EXIT_USAGE
    http_port = sock.getsockname()[1]
    console = Console(host, port, name=name, library=library, profile=profile,
                      poll_hz=args.poll_hz, battery=args.battery, autonomy=autonomy,
                      ssl_context=ssl_context)
    # ws="websockets-sansio": name the WebSocket implementation, so a missing library is an
    # import error at start rather than uvicorn quietly answering every upgrade with 404.
    serve_app(create_app(console), sock,
              lambda: print(f"ramp-teleop: open http://{HTTP_HOST}:{http_port}/", flush=True),
              ws="websockets-sansio", lifespan="on", graceful_s=2)
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
