"""`ramp run` and `ramp check`: the supervisor's command line (SPEC section 5)."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ramp import __version__
from ramp.common.files import why
from ramp.common.hostport import format_hostport
from ramp.config import Config, check_config, valid_host
from ramp.errors import ConfigError, PluginError, RampError

if TYPE_CHECKING:
    from ramp.runtime.observers import Observer

log = logging.getLogger("ramp")



class JournalFormatter(logging.Formatter):
    """Prefixes each line with its syslog priority (`<4>`), which journald reads, so
    `journalctl -p warning` finds warnings and errors."""

    PRIORITY = {logging.DEBUG: 7, logging.INFO: 6, logging.WARNING: 4, logging.ERROR: 3,
                logging.CRITICAL: 2}

    def format(self, record: logging.LogRecord) -> str:
        return f"<{self.PRIORITY.get(record.levelno, 6)}>{super().format(record)}"


def setup_logging(level: str) -> None:
    """One line per event, plain text; timestamps only on a terminal (journald adds its
    own), syslog priorities when stderr is connected to the journal."""
    fmt = "%(levelname)s %(name)s: %(message)s"
    if sys.stderr.isatty():
        fmt = "%(asctime)s " + fmt
    handler = logging.StreamHandler(sys.stderr)
    journal = bool(os.environ.get("JOURNAL_STREAM")) and not sys.stderr.isatty()
    handler.setFormatter(JournalFormatter(fmt) if journal else logging.Formatter(fmt))
    from ramp.common.logthrottle import install as throttle_repeats

    throttle_repeats(handler)  # a connect/close flood is a few lines and a count, not 1,140
    logging.basicConfig(level=getattr(logging, level.upper(), logging.INFO),
                        handlers=[handler], force=True)
    # `transitions` (the watchdog and the attachment machines) logs every transition at INFO;
    # our own lines already say what happened, so its lines appear only with --log-level debug.
    if level.lower() != "debug":
        logging.getLogger("transitions").setLevel(logging.WARNING)


def _print_errors(errors: list[ConfigError]) -> None:
    for err in errors:
        print(err, file=sys.stderr)


#: Exit status for a configuration error, from `ramp check` and `ramp run` alike (the systemd
#: unit does not restart on it: restarting cannot fix a file).
EXIT_CONFIG = 2


def cmd_check(args: argparse.Namespace) -> int:
    config, errors = check_config(args.file)
    if errors:
        _print_errors(errors)
        named = args.file if args.file.strip() else "(no file name)"  # `ramp check ""`
        print(f"{named}: {len(errors)} error{'s' if len(errors) != 1 else ''}", file=sys.stderr)
        if config is not None:  # only plugins whose code raised (see PluginError)
            print(f"{named}: `ramp run` would start the rest of the robot, with "
                  f"{'these' if len(errors) != 1 else 'this'} in fault", file=sys.stderr)
        return EXIT_CONFIG
    assert config is not None
    rules = len(config.interlocks)
    print(f"{args.file}: ok ({len(config.buses)} buses, {len(config.modules)} modules: "
          f"{', '.join(config.modules) or 'none'}"
          + (f"; {rules} interlock{'s' if rules != 1 else ''}" if rules else "") + ")")
    if getattr(args, "explain", False):  # what each interlock covers (SPEC 11)
        from ramp.config.interlocks import explain

        for line in explain(config.interlocks, config.modules) or ["no interlocks"]:
            print(line)
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    setup_logging(args.log_level)
    config, errors = check_config(args.config)
    if errors and (config is None or not all(isinstance(e, PluginError) for e in errors)):
        _print_errors(errors)
        return EXIT_CONFIG
    assert config is not None
    for err in errors:  # SPEC 2.2: a plugin that fails at start-up is its module's fault only
        log.error("%s; the rest of the robot starts without it", err)
    if not args.sim:
        sim_buses = [ConfigError("the sim driver stands in for hardware only under "
                                 "`ramp run --sim`; name the bus's real driver, or add --sim",
                                 file=config.file, line=bc.line, key=f"buses.{bc.name}.driver")
                     for bc in config.buses.values() if bc.driver == "sim"]
        if sim_buses:
            _print_errors(sim_buses)
            return EXIT_CONFIG
    from ramp.layers.server import ensure_fd_limit

    problem = ensure_fd_limit(config.server.max_clients, len(config.buses))
    if problem is not None:
        _print_errors([ConfigError(problem, file=config.file, key="server.max_clients",
                                   line=config.lines.get("server.max_clients", 0))])
        return EXIT_CONFIG
    return run_supervisor(config, sim=args.sim, host=args.host, port=args.port,
                          observer=getattr(args, "observer", None), record=args.record,
                          state_dir=args.state_dir)


def run_supervisor(config: Config, *, sim: bool, host: str | None, port: int | None,
                   observer: Observer | None = None, record: str | None = None,
                   state_dir: str | None = None, rt_priority: int | None = None) -> int:
    """Build, start and run until a stop signal, as the service runs
    (`ramp.runtime.service.serve`); motors are stopped before returning. `observer` (see
    `ramp.runtime.observers`) watches the running supervisor; `record` (`--record DIR`)
    records the run there, over the config's `recorder: dir`; latches are kept in
    `state_dir` (`--state-dir`, else `ramp.common.state_files.default_state_dir`);
    `rt_priority`: SCHED_FIFO at this priority where permitted (None: as started; the
    systemd unit sets it)."""
    from ramp.clock import MonotonicClock
    from ramp.common.state_files import default_state_dir
    from ramp.runtime import build
    from ramp.runtime.latch_state import LatchState, state_file
    from ramp.runtime.recording import recorder_for
    from ramp.runtime.service import STOP_SIGNALS, ServiceState, serve

    clock = MonotonicClock()
    backplane = None
    recorder = recorder_for(config, record, sim)
    try:  # building drivers and modules checks what the config check cannot see
        if sim:
            from ramp.simulation.backplane import (  # the one place ramp/ reaches firmware_like/
                RUN_PHYSICS_HZ,
                SimBackplane,
            )

            backplane = SimBackplane(config, physics_hz=RUN_PHYSICS_HZ, read_in_wait=False)
            sup = build(config, clock, backplane.bus_factory, host=host, port=port,
                        observer=observer, recorder=recorder)
            backplane.attach(sup)
        else:
            sup = build(config, clock, host=host, port=port, observer=observer,
                        recorder=recorder)
    except Exception as exc:  # noqa: BLE001 - nothing is open yet; say what and leave
        if backplane is not None:
            backplane.close()
        if isinstance(exc, ConfigError):
            _print_errors([ConfigError(exc.detail, file=exc.file or config.file,
                                       line=exc.line, key=exc.key)])
            return EXIT_CONFIG
        if isinstance(exc, RampError):
            log.error("cannot build the supervisor from %s: %s", config.file, exc)
        else:  # a bug: its traceback helps whoever reads the log
            log.exception("cannot build the supervisor from %s", config.file)
        return 1
    keep = Path(state_dir) if state_dir else default_state_dir()
    sup.latch_state = LatchState(state_file(keep, config.file), config.file)
    reloader = None
    if config.access.configured or config.server.tls is not None:
        # A deployed robot (SPEC 13): SIGHUP reloads `access` (systemd's ExecReload), as
        # daemons do; without an access section it stops the robot like the others.
        from ramp.runtime.access_reload import AccessReloader

        reloader = AccessReloader(sup, config.file)

    def announce(state: ServiceState) -> None:
        h, p = sup.server.address
        # an IPv6 address in brackets (`[::1]:5577`), as ramp-shell and every client take it
        print(f"ramp: ready on {format_hostport(h, p)}", flush=True)

    def closed() -> None:
        if reloader is not None:
            reloader.close()
        if backplane is not None:
            backplane.close()

    stop_signals: tuple[signal.Signals, ...] = STOP_SIGNALS
    if reloader is not None:  # SIGHUP is the reloader's
        stop_signals = tuple(s for s in STOP_SIGNALS if s != signal.SIGHUP)
        reloader.install()
    code = serve(sup, ready=announce, rt_priority=rt_priority, stop_signals=stop_signals,
                 on_stop=closed)
    if code == 0:
        log.info("stopped: every motor commanded to zero")
    return code


def port_number(text: str) -> int:
    """`--port`: 0-65535 (0 picks a free port); anything else is a usage error (exit 2)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a TCP port (0-65535)") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port} is not a TCP port (0-65535)")
    return port


def host_name(text: str) -> str:
    """`--host`: an IP address or a host name, checked as `server.host` is."""
    if not valid_host(text):
        raise argparse.ArgumentTypeError(f"{text!r} is not an IP address or host name")
    return text


def record_dir(text: str) -> str:
    """`--record DIR`: a directory path (made if missing, here, as the command line is read;
    relative to the working directory). A path that can never be a directory (a file, a
    device, a path below a file) is a usage error: the supervisor used to run for hours
    recording nothing, with one warning every 5 s."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a directory for the MCAP files")
    try:
        Path(text).mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise argparse.ArgumentTypeError(
            f"cannot record into {text}: it is not a directory; expected a directory for "
            "the MCAP files") from None
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"cannot record into {text}: {why(exc)}") from None
    return text


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ramp", description=__doc__)
    parser.add_argument("--version", action="version", version=f"ramp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run the supervisor")
    run.add_argument("--config", default="ramp.yaml", help="config file (default ./ramp.yaml)")
    run.add_argument("--sim", action="store_true",
                     help="replace every bus (except those with sim: false) by its emulator")
    run.add_argument("--host", type=host_name, default=None,
                     help="address to serve on (default: from config)")
    run.add_argument("--port", type=port_number, default=None,
                     help="TCP port, 0-65535 (0 picks a free one)")
    run.add_argument("--record", metavar="DIR", type=record_dir, default=None,
                     help="record the run into MCAP files in DIR (over the config's "
                          "recorder: dir; see `ramp log`)")
    run.add_argument("--state-dir", metavar="DIR", default=None,
                     help="where latched faults and interlocks are kept across restarts "
                          "(default $STATE_DIRECTORY, else ~/.local/state/ramp)")
    run.add_argument("--log-level", default="info",
                     choices=["debug", "info", "warning", "error"])
    run.set_defaults(func=cmd_run)
    check = sub.add_parser("check", help="validate a config file without touching hardware")
    check.add_argument("file", nargs="?", default="ramp.yaml")
    check.add_argument("--explain", action="store_true",
                       help="list, per interlock rule, every function it covers")
    check.set_defaults(func=cmd_check)
    from ramp.simulation.commands import add_sim_parser  # `ramp sim …`: lazy, light to import

    add_sim_parser(sub)
    from ramp.recorder.logcli import add_log_parser  # `ramp log summary|plot FILE.mcap`

    add_log_parser(sub)
    from ramp.certs.cli import add_certs_parser  # `ramp certs init|issue|list` (SPEC 13)

    add_certs_parser(sub)
    from ramp.fleet.commands import add_fleet_parser  # `ramp fleet init|...` (SPEC 14)

    add_fleet_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None, observer: Observer | None = None) -> int:
    """`ramp ...`; `observer` watches the supervisor of `ramp run` (the benchmarks use it)."""
    args = build_parser().parse_args(argv)
    args.observer = observer
    code: int = args.func(args)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
