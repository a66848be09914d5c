"""`ramp sim mission`: one whole RMC run in the simulator, from the command line (SPEC 6.3).

    ramp sim mission [--seed N] [--start-box left|right] [--heading 0|90|180|270]
                     [--world FILE] [--fault none|gyro-drift|imu-shift] [--duration 600]
                     [--config autonomy.yaml] [--json] [--trace FILE] [--plot FILE.png]
                     [--record FILE.mcap] [--foxglove-port P] [--realtime [--port P]]

Without `--start-box`/`--heading` the seed chooses them the way `ramp sim campaign` does
((seed mod 8) walks left/right x 0/90/180/270), so a campaign's run repeats alone from its
seed; with `--world` the file's start holds unless they are given. Prints each state change
as it happens, then a summary (`--json`: the last line is SPEC 6.3's JSON object).

Exit status: 0 when at least 10 kg were delivered with no collision and no crater entry, 1
when the run did not qualify, 2 on a usage, world-file or config error.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
from pathlib import Path
from typing import Any

from ramp.common.outputs import figure_file, output_file, plot_unavailable

HEADINGS = (0, 90, 180, 270)
REALTIME_PORT = 5577  # `ramp run`'s port: what ramp-shell and ramp-teleop try first


def add_mission_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "mission", help="run a whole RMC mission: backend, emulators and the autonomy",
        description="Run the backend, every emulator and the autonomy together on one "
                    "virtual clock (the autonomy over real MCP and SCIP TCP connections), "
                    "print each state change and a summary. The same arguments give the "
                    "same run.")
    where = p.add_argument_group("world (the SPEC 6.1 arena)")
    where.add_argument("--seed", type=int, default=0, metavar="N",
                       help="seed of the layout, the start, the sensors' noise and the "
                            "fault (default 0)")
    where.add_argument("--start-box", choices=("left", "right"), default=None,
                       help="start box (default: from the seed, as ramp sim campaign does)")
    where.add_argument("--heading", type=int, choices=HEADINGS, default=None,
                       help="start heading in degrees (default: from the seed)")
    where.add_argument("--world", metavar="FILE",
                       help="world file (YAML: start, rocks, craters) instead of a seeded "
                            "layout")
    p.add_argument("--fault", choices=("none", "gyro-drift", "imu-shift"), default="none",
                   help="IMU fault to inject (SPEC 6.2; default none)")
    p.add_argument("--randomize", action="store_true",
                   help="the seed also draws the robot's physics and calibration: skid "
                        "efficiency, traction, wheel speeds, the LIDAR mount, a gyro bias, "
                        "the load cell's gain, battery sag (SPEC 6.3); printed in the "
                        "summary, not told to the autonomy")
    p.add_argument("--duration", type=float, default=600.0, metavar="S",
                   help="the run's length in simulated seconds (default 600)")
    p.add_argument("--config", metavar="FILE",
                   help="the autonomy's config (default: the repository's autonomy.yaml)")
    p.add_argument("--json", action="store_true",
                   help="end with one JSON object (the summary) as the last line")
    p.add_argument("--trace", type=output_file, metavar="FILE",
                   help="write the ground truth as JSON lines: a header with the true world, "
                        "then t, x, y, yaw, lift, bin_kg, delivered_kg, state every 0.1 s")
    p.add_argument("--plot", type=figure_file, metavar="FILE.png",
                   help="draw the arena, true and detected obstacles, planned and driven "
                        "paths")
    p.add_argument("--record", type=output_file, metavar="FILE.mcap",
                   help="record the autonomy's view (mission state, true and estimated "
                        "pose) into an MCAP file")
    p.add_argument("--foxglove-port", type=int, default=None, metavar="P",
                   help="stream the same channels live to Foxglove over its WebSocket "
                        "protocol on 127.0.0.1:P (0 picks a free port; printed); best with "
                        "--realtime")
    # (ramp.autonomy.live.foxglove_live.add_host_arguments' flags; not imported here: every
    # `ramp` command builds this parser, and the SBC's `ramp run` should not load the view)
    p.add_argument("--foxglove-host", default="127.0.0.1", metavar="HOST",
                   help="where the live view listens (default 127.0.0.1); any other address "
                        "needs --foxglove-cert and --foxglove-key (wss://)")
    p.add_argument("--foxglove-cert", metavar="FILE", help="the live view's certificate")
    p.add_argument("--foxglove-key", metavar="FILE", help="its private key")
    p.add_argument("--command-port", type=int, default=None,
                   help="with --realtime: the autonomy's command endpoint for a fleet agent "
                   "(JSON lines on loopback; 0 picks a port); the mission then waits for "
                   "the fleet's rmcMission")
    p.add_argument("--realtime", action="store_true",
                   help="run on the wall clock and serve MCP (see --port) so an operator "
                        "can watch with ramp-shell or ramp-teleop and take over; the robot "
                        "and the arena run in a process of their own, as on the robot")
    p.add_argument("--port", type=int, default=None, metavar="P",
                   help=f"with --realtime: the MCP port (default {REALTIME_PORT}; 0 picks "
                        "a free one)")
    # Realtime as it ran before issue 23: the backend and the simulator on the autonomy's
    # loop, in one process. Kept only so `python -m bench --only realtime` can measure what
    # the separate process buys; hidden from --help.
    p.add_argument("--single-loop", action="store_true", help=argparse.SUPPRESS)
    # The backend's process runs SCHED_FIFO at the service's priority where permitted, as the
    # service does; this runs it at the default priority instead, so the benchmark can say
    # what the priority buys. Hidden from --help.
    p.add_argument("--backend-default-priority", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_mission)


class UsageError(Exception):
    """A bad argument: `ramp sim mission: what was expected`, exit 2."""


def cmd_mission(args: argparse.Namespace) -> int:
    try:
        return _mission(args)
    except UsageError as exc:
        print(f"ramp sim mission: {exc}", file=sys.stderr)
        return 2


def _mission(args: argparse.Namespace) -> int:
    from firmware_like.world_file import WorldFileError
    from ramp.common.files import why
    from ramp.errors import ConfigErrors
    from ramp.simulation.arena_process import ArenaError
    from ramp.simulation.arguments import ArgumentError, check_duration, check_seed
    from ramp.simulation.campaign import combination
    from ramp.simulation.mission import MissionOptions, MissionRun

    try:
        check_seed(args.seed)
        check_duration(args.duration)
    except ArgumentError as exc:
        raise UsageError(str(exc)) from exc
    if args.port is not None and not args.realtime:
        raise UsageError("--port: only with --realtime (the virtual-time run serves MCP on "
                         "a loopback port of its own)")
    if args.port is not None and not 0 <= args.port <= 65535:
        raise UsageError(f"--port: expected 0-65535, got {args.port}")
    if args.command_port is not None and not args.realtime:
        raise UsageError("--command-port: only with --realtime (a fleet supervises robots "
                         "on the wall clock)")
    if args.command_port is not None and not 0 <= args.command_port <= 65535:
        raise UsageError(f"--command-port: expected 0-65535, got {args.command_port}")
    if args.single_loop and not args.realtime:
        raise UsageError("--single-loop: only with --realtime")
    if args.foxglove_port is not None and not 0 <= args.foxglove_port <= 65535:
        raise UsageError(f"--foxglove-port: expected 0-65535, got {args.foxglove_port}")
    box, heading = args.start_box, args.heading
    if args.world is None and box is None and heading is None:
        box, heading = combination(args.seed)
    options = MissionOptions(seed=args.seed, start_box=box, heading=heading, fault=args.fault,
                             duration=args.duration, world=args.world, config=args.config,
                             realtime=args.realtime, randomize=args.randomize,
                             single_loop=args.single_loop, command_port=args.command_port,
                             **({"backend_rt_priority": None}
                                if args.backend_default_priority else {}),
                             port=(REALTIME_PORT if args.port is None else args.port)
                             if args.realtime else 0)
    no_plot = plot_unavailable(args.plot)
    if no_plot is not None:
        raise UsageError(no_plot)
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")
    try:
        trace = open(args.trace, "w", encoding="utf-8") if args.trace else None  # noqa: SIM115
    except OSError as exc:
        raise UsageError(f"--trace: cannot write {args.trace}: {why(exc)}") from exc
    try:
        try:
            run = MissionRun(options, trace_file=trace)
            run.on_change = lambda change: _print_change(run, change)
        except WorldFileError as exc:
            for err in exc.errors:
                print(err, file=sys.stderr)
            return 2
        except ConfigErrors as exc:
            for problem in exc.errors:
                print(problem, file=sys.stderr)
            return 2
        except ValueError as exc:
            raise UsageError(str(exc)) from exc
        try:
            if args.record or args.foxglove_port is not None:
                _watch(run, args)
            if args.realtime and run.autonomy is None:
                run.build()
        except ArenaError as exc:  # the simulator's process could not start (a port in use)
            run.close()
            print(f"ramp sim mission: {exc}", file=sys.stderr)
            return 1
        except BaseException:
            run.close()  # a child already started must not outlive the command
            raise
        if args.realtime:
            host, port = run.mcp_address
            print(f"ramp sim mission: running on the wall clock; MCP on {host}:{port} "
                  f"(watch: ramp-shell {host}:{port}; take over: "
                  "robot:control.acquire=(operator)); Ctrl-C ends the run", flush=True)
            if run.commands is not None:
                chost, cport = run.commands.address
                print(f"ramp sim mission: autonomy commands on {chost}:{cport} (the mission "
                      "waits for rmcMission)", flush=True)
            if run.arena is not None:
                service = run.arena.service
                print(f"ramp sim mission: the backend runs in process {run.arena.backend_pid} "
                      f"as `ramp run` runs ({service.get('policy', '?')}; stall guard "
                      f"{'on' if service.get('stall_guard') else 'off'}), the simulated "
                      f"hardware and the arena in process {run.arena.pid}, the autonomy in "
                      f"process {os.getpid()}", flush=True)
            signal.signal(signal.SIGTERM, _interrupt)
        summary = run.run()
    finally:
        if trace is not None:
            trace.close()
    if args.trace:
        summary["trace"] = args.trace
        summary["referee"] = _referee(args.trace)
    code = 0 if summary["qualified"] else 1
    if args.plot:
        from ramp.simulation.mission_plot import draw_mission

        try:
            draw_mission(run, args.plot)
            summary["plot"] = args.plot
        except OSError as exc:  # the disk filled up during the run, say
            print(f"ramp sim mission: --plot: cannot write {args.plot}: {why(exc)}",
                  file=sys.stderr)
            code = 1
    if args.record:
        summary["record"] = args.record
    for line in describe(summary):
        print(line)
    if args.json:
        print(json.dumps(summary))
    return code


def _watch(run: Any, args: argparse.Namespace) -> None:
    """`--record` and `--foxglove-port`: the autonomy's view (and the truth) into a file, to
    Foxglove live, or both. The live view listens before the run, so its address is known."""
    from ramp.simulation.mission_record import MissionRecorder

    live = None
    if args.foxglove_port is not None:
        from ramp.autonomy.live import FoxgloveLive, LiveViewError
        from ramp.autonomy.live.foxglove_live import server_tls
        from ramp.autonomy.live.view import LATCHED

        try:
            live = FoxgloveLive(port=args.foxglove_port, name="ramp sim mission",
                                latched=LATCHED, host=args.foxglove_host,
                                ssl_context=server_tls(args.foxglove_cert, args.foxglove_key))
        except (ValueError, LiveViewError) as exc:
            raise UsageError(f"--foxglove-host: {exc}") from exc
    watcher = MissionRecorder(args.record, live=live)
    run.observers.append(watcher)
    if live is None:
        return
    from ramp.autonomy.live import LiveViewError

    run.build()
    try:
        watcher.start(run.clock.now())
    except LiveViewError as exc:
        watcher.abandon()
        run.close()
        raise UsageError(f"--foxglove-port: {exc}") from exc
    print(f"ramp sim mission: foxglove live on {live.url}", flush=True)


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _print_change(run: Any, change: Any) -> None:
    t = run.mission_time(change.t)
    print(f"{t:7.1f} s  {change.source} -> {change.dest} ({change.reason})", flush=True)


def _referee(path: str) -> dict[str, Any]:
    """The trace refereed on its own (`ramp.simulation.referee`), as a cross-check."""
    from ramp.simulation.referee import TraceError, referee

    try:
        r = referee(Path(path))
    except TraceError as exc:  # a run that failed before its first sample
        return {"error": str(exc)}
    return {"collisions": r.collisions, "crater_entries": r.crater_entries,
            "delivered_at_collector_kg": round(r.delivered_at_collector_kg, 3),
            "delivered_elsewhere_kg": round(r.delivered_elsewhere_kg, 3),
            "qualifies": r.qualifies}


def describe(s: dict[str, Any]) -> list[str]:
    """The summary in a few lines a person reads."""
    out = [f"{s['world']}: start {s['start_box']} box heading {s['heading']}, fault "
           f"{s['fault']}, {s['duration_s']:g} s run",
           f"  outcome       {s['outcome']} (final state {s['final_state']})",
           f"  delivered     {s['delivered_kg']:.2f} kg in {s['deposits']} deposit(s) "
           f"({s['excavated_kg']:.2f} kg dug, {s['spilled_kg']:.2f} kg spilled)",
           f"  collisions    {s['collisions']}, crater entries {s['crater_entries']}",
           f"  localization  {s['localization_losses']} loss(es), {s['faults']} fault(s) "
           "recovered or not",
           f"  time          {s['sim_time_s']:.1f} s simulated in {s['wall_time_s']:.1f} s "
           f"({s['rtf'] or 0:.0f}x real time, "
           f"{'compiled hot path' if s.get('compiled') else 'plain Python'})",
           "  " + ("QUALIFIED: >= 10 kg, no collision, no crater entry" if s["qualified"]
                   else "not qualified (needs >= 10 kg, no collision, no crater entry)")]
    if s.get("last_problem"):
        out.insert(5, f"  last problem  {s['last_problem']}")
    if s.get("error"):
        out.insert(1, f"  error         {s['error']}")
    if "referee" in s:
        r = s["referee"]
        if "error" in r:
            out.append(f"  trace         {s['trace']}: not refereed: {r['error']}")
        else:
            out.append(f"  trace         {s['trace']}: refereed {r['collisions']} "
                       f"collision(s), {r['crater_entries']} crater entr(y/ies), "
                       f"{r['delivered_at_collector_kg']:.2f} kg at the collector")
    if s.get("randomized"):
        out.append("  randomized    " + ", ".join(f"{k} {v:g}" for k, v in
                                                  s["randomized"].items()))
    for key in ("plot", "record"):
        if s.get(key):
            out.append(f"  {key:13s} {s[key]}")
    return out
