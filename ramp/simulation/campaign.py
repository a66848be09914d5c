"""`ramp sim campaign`: many seeded missions, on every local core or on a Dask cluster (SPEC 9).

    ramp sim campaign --runs N [--seed S] [--fault none|gyro-drift|imu-shift] [--workers W]
                      [--cluster tcp://HOST:PORT] [--json]

Run i gets seed S + i and a start box and heading from that seed: (S + i) mod 8 picks one
of the 8 combinations (left/right x 0/90/180/270), so consecutive seeds cover them all and a
run can be repeated from its seed alone with `ramp sim mission`. Missions run in separate
processes (spawned, so each starts clean), `--workers` of them at once (default: every core
this process may use); with `--cluster` the same function runs on the workers of an
existing Dask distributed scheduler instead (the `cluster` extra; the workers need RAMP
installed too). The result is the same either way: rows come back in run order.

The mission is a function named by import path (`--mission`, default
`ramp.simulation.mission:run_mission`):

    run_mission(seed: int, start_box: str, heading: int, fault: str, duration: float) -> dict

returning SPEC 6.3's JSON summary (`outcome`, `delivered_kg`, `collisions`,
`crater_entries`, `localization_losses`, `sim_time_s`, `wall_time_s`, ...). A run that raises,
or returns no such summary, is an `error` row; the others still run.

A run succeeds when it delivered at least 10 kg with no collision and no crater entry.
Exit status: 0 when every run returned a summary, 1 when some run failed with an error,
2 on a usage error (bad arguments, a mission that cannot be imported, no cluster there).
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import os
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from ramp.common.hostport import parse_hostport
from ramp.simulation.arguments import (
    ArgumentError,
    check_duration,
    check_runs,
    check_seed,
    check_workers,
)

DEFAULT_MISSION = "ramp.simulation.mission:run_mission"
FAULTS = ("none", "gyro-drift", "imu-shift")
START_BOXES = ("left", "right")  # SPEC 6.1 (ramp.autonomy.arena has the same)
HEADINGS = (0, 90, 180, 270)
QUALIFY_KG = 10.0
SUMMARY_FIELDS = ("outcome", "delivered_kg", "collisions", "crater_entries")

MissionFn = Callable[[int, str, int, str, float], dict[str, Any]]


class CampaignError(Exception):
    """A campaign that cannot start: the message says what to fix."""


@dataclass(frozen=True)
class RunSpec:
    """One mission of a campaign: everything a worker needs, picklable."""

    index: int
    seed: int
    start_box: str
    heading: int
    fault: str
    duration: float
    mission: str  # "module:function"
    randomize: bool = False  # passed to the mission as randomize=True only when set


def combination(seed: int) -> tuple[str, int]:
    """The start box and heading of a seed: (seed mod 8) walks all 8 combinations."""
    k = seed % (len(START_BOXES) * len(HEADINGS))
    return START_BOXES[k % len(START_BOXES)], HEADINGS[k // len(START_BOXES)]


def plan_runs(runs: int, seed: int = 0, fault: str = "none", duration: float = 600.0,
              mission: str = DEFAULT_MISSION, randomize: bool = False) -> list[RunSpec]:
    """The campaign's runs, in order: run i has seed `seed + i`."""
    if runs < 1:
        raise CampaignError(f"--runs must be at least 1, got {runs}")
    if fault not in FAULTS:
        raise CampaignError(f"--fault must be one of {', '.join(FAULTS)}, got {fault!r}")
    specs = []
    for i in range(runs):
        box, heading = combination(seed + i)
        specs.append(RunSpec(i, seed + i, box, heading, fault, duration, mission, randomize))
    return specs


def load_mission(path: str) -> MissionFn:
    """Import `module:function`; CampaignError says why not."""
    module_name, _, attr = path.partition(":")
    if not module_name or not attr:
        raise CampaignError(f"mission {path!r}: expected module:function")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise CampaignError(f"mission {path!r}: cannot import {module_name}: {exc}") from exc
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise CampaignError(f"mission {path!r}: {module_name} has no function {attr}")
    return fn


def run_one(spec: RunSpec) -> dict[str, Any]:
    """Run one mission (in a worker process) and return its table row."""
    row: dict[str, Any] = {"run": spec.index, "seed": spec.seed, "start_box": spec.start_box,
                           "heading": spec.heading, "fault": spec.fault}
    # Wall time of a whole mission is what a campaign reports; this is a command-line tool,
    # not control code, so the wall clock is the right clock here.
    started = time.perf_counter()
    _log_errors_only()
    try:
        extra = {"randomize": True} if spec.randomize else {}
        summary = load_mission(spec.mission)(spec.seed, spec.start_box, spec.heading,
                                             spec.fault, spec.duration, **extra)
        if not isinstance(summary, dict):
            raise TypeError(f"the mission returned {type(summary).__name__}, not a summary "
                            "dict")
        missing = [k for k in SUMMARY_FIELDS if k not in summary]
        if missing:
            raise ValueError(f"the mission's summary lacks {', '.join(missing)}")
    except Exception as exc:  # noqa: BLE001 - one broken run must not end the campaign
        row.update(outcome="error", error=f"{type(exc).__name__}: {exc}",
                   traceback=traceback.format_exc(limit=5),
                   wall_time_s=round(time.perf_counter() - started, 3))
        return row
    wall = round(time.perf_counter() - started, 3)
    row.update({
        "outcome": str(summary["outcome"]),
        "delivered_kg": float(summary["delivered_kg"]),
        "collisions": int(summary["collisions"]),
        "crater_entries": int(summary["crater_entries"]),
        "localization_losses": summary.get("localization_losses"),
        "sim_time_s": summary.get("sim_time_s"),
        "wall_time_s": wall,  # measured here, the same way for any mission
        "summary": summary,
    })
    return row


def _log_errors_only() -> None:
    """A worker logs errors only, as `ramp sim mission` does: a fresh (spawned) process has
    no logging set up, and Python's last-resort handler would print every warning of every
    run (each interlock engaging, each re-plan) between the progress bar's lines. What a
    run did is in its row and summary."""
    root = logging.getLogger()
    if not root.handlers:
        logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")


def succeeded(row: dict[str, Any]) -> bool:
    """SPEC 6.3 / issue 11: at least 10 kg delivered, no collision, no crater entry."""
    return (row.get("outcome") != "error" and row.get("delivered_kg", 0.0) >= QUALIFY_KG
            and row.get("collisions") == 0 and row.get("crater_entries") == 0)


def default_workers() -> int:
    """Every core this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def run_campaign(specs: Sequence[RunSpec], *, workers: int | None = None,
                 cluster: str | None = None,
                 on_result: Callable[[dict[str, Any]], None] | None = None,
                 ) -> list[dict[str, Any]]:
    """Run every spec, locally in processes or on a Dask cluster; rows in run order.

    `on_result` is called in this process as each run finishes (for a progress bar).
    """
    if cluster is not None:
        rows = _run_on_cluster(specs, cluster, on_result)
    else:
        rows = _run_locally(specs, workers or default_workers(), on_result)
    return sorted(rows, key=lambda r: int(r["run"]))


def _run_locally(specs: Sequence[RunSpec], workers: int,
                 on_result: Callable[[dict[str, Any]], None] | None) -> list[dict[str, Any]]:
    # Imported here: `ramp run` builds every subcommand's parser, this one's too, and the
    # process pool's modules are 4 MB of a supervisor that never runs a campaign.
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from multiprocessing import get_context

    rows = []
    # spawn: each worker starts from a fresh interpreter (no inherited sockets, threads or
    # state), so a run is the same whether it is the first or the hundredth in its process.
    with ProcessPoolExecutor(max_workers=max(1, min(workers, len(specs))),
                             mp_context=get_context("spawn")) as pool:
        futures = [pool.submit(run_one, spec) for spec in specs]
        try:
            for fut in as_completed(futures):
                row = fut.result()
                rows.append(row)
                if on_result is not None:
                    on_result(row)
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise
    return rows


def _run_on_cluster(specs: Sequence[RunSpec], address: str,
                    on_result: Callable[[dict[str, Any]], None] | None) -> list[dict[str, Any]]:
    try:
        from distributed import Client
        from distributed import as_completed as dask_completed
    except ImportError as exc:
        raise CampaignError("--cluster needs Dask distributed: pip install 'ramp[cluster]'") \
            from exc
    try:
        client = Client(address, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise CampaignError(f"--cluster {address}: cannot reach the scheduler: {exc}") from exc
    rows = []
    try:
        futures = client.map(run_one, list(specs), pure=False)
        for fut in dask_completed(futures):
            row = fut.result()
            rows.append(row)
            if on_result is not None:
                on_result(row)
    finally:
        client.close()
    return rows


def report(specs: Sequence[RunSpec], rows: Sequence[dict[str, Any]], *, workers: int | None,
           cluster: str | None, wall_time_s: float) -> dict[str, Any]:
    """The whole campaign as one JSON-able object."""
    ok = sum(succeeded(r) for r in rows)
    first = specs[0]
    return {
        "runs": len(rows),
        "succeeded": ok,
        "success_rate": round(ok / len(rows), 4) if rows else 0.0,
        "errors": sum(r["outcome"] == "error" for r in rows),
        "seed": first.seed,
        "fault": first.fault,
        "duration_s": first.duration,
        "mission": first.mission,
        "randomize": first.randomize,
        "workers": None if cluster else workers,
        "cluster": cluster,
        "wall_time_s": round(wall_time_s, 3),
        "results": [{k: v for k, v in r.items() if k != "traceback"} for r in rows],
    }


# -- command line ----------------------------------------------------------------------------
def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register `campaign` under `ramp sim`'s subparsers."""
    p = subparsers.add_parser(
        "campaign", help="run many seeded missions and report the success rate",
        description="Run N seeded missions across both start boxes and all four headings, "
                    "on every local core or on a Dask cluster, and print a table and the "
                    "success rate (>= 10 kg delivered, no collision, no crater entry).")
    p.add_argument("--runs", type=int, required=True, metavar="N", help="number of missions")
    p.add_argument("--seed", type=int, default=0, metavar="S",
                   help="seed of the first run; run i gets S + i (default 0)")
    p.add_argument("--fault", choices=FAULTS, default="none", help="IMU fault in every run")
    p.add_argument("--workers", type=int, default=None, metavar="W",
                   help="processes at once (default: every core)")
    p.add_argument("--cluster", default=None, metavar="tcp://HOST:PORT",
                   help="run on this Dask distributed scheduler instead (extra: cluster)")
    p.add_argument("--duration", type=float, default=600.0, metavar="S",
                   help="simulated seconds per mission (default 600)")
    p.add_argument("--randomize", action="store_true",
                   help="each run's seed also draws the robot's physics and calibration "
                        "(SPEC 6.3; the autonomy is not told)")
    p.add_argument("--mission", default=DEFAULT_MISSION, metavar="MODULE:FUNCTION",
                   help=f"the mission function (default {DEFAULT_MISSION})")
    p.add_argument("--json", action="store_true",
                   help="print the whole report as one JSON object (the last line)")
    p.set_defaults(func=main)
    return p


def check_cluster_address(address: str) -> None:
    """`tcp://HOST:PORT` (the scheme Dask's scheduler prints); CampaignError says why not."""
    scheme, sep, rest = address.partition("://")
    if not sep or scheme not in ("tcp", "tls"):
        raise CampaignError(f"--cluster {address!r}: expected tcp://HOST:PORT")
    try:
        parse_hostport(rest, example="10.0.0.5:8786")
    except ValueError as exc:
        raise CampaignError(f"--cluster {address!r}: {exc}") from None


def main(args: argparse.Namespace) -> int:
    """Run the campaign the arguments describe; print the table or the JSON report."""
    try:
        from rich.console import Console
    except ImportError:
        sys.stderr.write("ramp sim campaign needs rich: pip install 'ramp[sim]'\n")
        return 2
    err = Console(stderr=True)
    try:
        try:
            check_runs(args.runs)
            check_seed(args.seed, args.runs)
            check_workers(args.workers)
            check_duration(args.duration)
        except ArgumentError as exc:
            raise CampaignError(str(exc)) from exc
        if args.cluster is not None:
            check_cluster_address(args.cluster)
        specs = plan_runs(args.runs, args.seed, args.fault, args.duration, args.mission,
                          args.randomize)
        load_mission(args.mission)  # fail here, not in every worker
        workers = None if args.cluster else min(args.workers or default_workers(), len(specs))
        started = time.perf_counter()
        rows = _with_progress(specs, workers, args.cluster, err)
        wall = time.perf_counter() - started
    except CampaignError as exc:
        err.print(f"ramp sim campaign: {exc}", style="red", highlight=False, soft_wrap=True)
        return 2
    doc = report(specs, rows, workers=workers, cluster=args.cluster, wall_time_s=wall)
    if args.json:
        sys.stdout.write(json.dumps(doc) + "\n")
    else:
        _print_table(doc, rows)
    for row in rows:
        if row["outcome"] == "error":
            err.print(f"run {row['run']} (seed {row['seed']}): {row['error']}",
                      style="red", highlight=False, soft_wrap=True)
    return 1 if doc["errors"] else 0


def _with_progress(specs: Sequence[RunSpec], workers: int | None, cluster: str | None,
                   console: Any) -> list[dict[str, Any]]:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    where = f"cluster {cluster}" if cluster else f"{workers} process(es)"
    counts = {"ok": 0, "not": 0}
    with Progress(TextColumn("[bold]missions[/] on " + where), BarColumn(),
                  MofNCompleteColumn(), TextColumn("{task.fields[tally]}"),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=console,
                  transient=False) as progress:
        task = progress.add_task("missions", total=len(specs), tally="")

        def on_result(row: dict[str, Any]) -> None:
            counts["ok" if succeeded(row) else "not"] += 1
            progress.update(task, advance=1,
                            tally=f"{counts['ok']} ok, {counts['not']} not")

        return run_campaign(specs, workers=workers, cluster=cluster, on_result=on_result)


def _fmt(value: Any, digits: int = 1) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def _print_table(doc: dict[str, Any], rows: Iterable[dict[str, Any]]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"ramp sim campaign: {doc['runs']} runs from seed {doc['seed']}, "
                        f"fault {doc['fault']}"
                        + (", randomized" if doc.get("randomize") else ""))
    for name in ("seed", "box", "heading", "fault", "outcome", "delivered kg", "collisions",
                 "crater entries", "losses", "sim time s", "wall time s", "ok"):
        table.add_column(name, justify="left" if name in ("box", "fault", "outcome") else
                         "right")
    for r in rows:
        table.add_row(str(r["seed"]), r["start_box"], str(r["heading"]), r["fault"],
                      r["outcome"], _fmt(r.get("delivered_kg"), 2), _fmt(r.get("collisions")),
                      _fmt(r.get("crater_entries")), _fmt(r.get("localization_losses")),
                      _fmt(r.get("sim_time_s")), _fmt(r.get("wall_time_s"), 2),
                      "yes" if succeeded(r) else "no")
    out = Console(highlight=False)
    if not out.is_terminal:  # a file or a pipe gets every column whole, not 80 wide
        out = Console(highlight=False, width=160)
    out.print(table)
    out.print(f"success rate: {doc['succeeded']}/{doc['runs']} = "
              f"{100.0 * doc['success_rate']:.1f} % (>= {QUALIFY_KG:g} kg delivered, "
              f"no collision, no crater entry); wall time {doc['wall_time_s']:.1f} s")


def cli(argv: Sequence[str] | None = None) -> int:
    """`python -m ramp.simulation.campaign ...`: the command on its own, as under `ramp sim`."""
    parser = argparse.ArgumentParser(prog="ramp sim")
    sub = parser.add_subparsers(dest="sim_command", required=True)
    add_parser(sub)
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(cli(sys.argv[1:] if len(sys.argv) > 1 and sys.argv[1] == "campaign"
                 else ["campaign", *sys.argv[1:]]))
