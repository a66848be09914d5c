"""`ramp log summary FILE.mcap` and `ramp log plot FILE.mcap -o FILE.png` (SPEC section 8).

Both read one or more recordings (several files of one run, oldest first: the recorder's
file names sort that way), including files cut short by a crash, and show a progress bar
while reading a large one.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ramp.common.outputs import figure_file


def _recording(text: str) -> Path:
    """A recording's path; an empty one is a usage error (`Path("")` is `.`, and the command
    said `.: cannot read: it is a directory`)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a recording (FILE.mcap), got an empty name")
    return Path(text)


def add_log_parser(sub: Any) -> argparse.ArgumentParser:
    """Register `log summary` and `log plot` on an argparse subparsers object."""
    log = sub.add_parser("log", help="read flight recordings (MCAP files)",
                         description=__doc__,
                         formatter_class=argparse.RawDescriptionHelpFormatter)
    cmds = log.add_subparsers(dest="log_command", required=True)
    summary = cmds.add_parser("summary", help="what happened in a recorded run")
    summary.add_argument("files", nargs="+", type=_recording, metavar="FILE.mcap")
    summary.add_argument("--json", action="store_true", help="one JSON document on stdout")
    _progress_flags(summary)
    summary.set_defaults(func=cmd_summary)
    plot = cmds.add_parser("plot", help="draw a recorded run's time series")
    plot.add_argument("files", nargs="+", type=_recording, metavar="FILE.mcap")
    plot.add_argument("-o", "--out", type=_output_path, required=True, metavar="FILE.png",
                      help="the picture to write (PNG; .svg and .pdf work too)")
    plot.add_argument("--title", default=None, help="title (default: the file names)")
    _progress_flags(plot)
    plot.set_defaults(func=cmd_plot)
    return log


def _output_path(text: str) -> Path:
    """`-o FILE.png`, checked before the recordings are read."""
    return Path(figure_file(text))


def _progress_flags(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--progress", dest="progress", action="store_true", default=None,
                   help="always show a progress bar (default: for files of 8 MB or more, "
                        "on a terminal)")
    g.add_argument("--no-progress", dest="progress", action="store_false")


def cmd_summary(args: argparse.Namespace) -> int:
    from ramp.recorder.reading import BadRecording, Recording
    from ramp.recorder.summary import Summary, format_report

    rec = Recording(args.files, progress=args.progress)
    s = Summary()
    try:
        for msg in rec:
            s.add(msg)
    except BadRecording as exc:
        print(f"ramp log: {exc}", file=sys.stderr)
        return 2
    report = s.report(rec.files)
    text = json.dumps(report, indent=2) if args.json else escape_controls(format_report(report))
    return write_out(text)


#: Control characters a recorded `/log` message may carry (ESC starts a terminal escape
#: sequence, BEL rings): every C0 character but newline and tab, DEL, and C1.
_CONTROLS = {c: f"\\x{c:02x}" for c in (*range(0x20), 0x7F, *range(0x80, 0xA0))
             if c not in (0x0A, 0x09)}


def escape_controls(text: str) -> str:
    """`text` with its control characters shown as `\\x1b`, never sent to the terminal: a
    recording is data from the robot, and its log lines must not drive the reader's
    terminal (move the cursor, retitle the window, hide what follows)."""
    return text.translate(_CONTROLS)


def write_out(text: str) -> int:
    """Print `text`; a reader that stops early (`| head`) ends the output quietly, as `cat`
    does, not with a BrokenPipeError traceback."""
    try:
        sys.stdout.write(text + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        # Python flushes stdout again at exit: point it at /dev/null so that is quiet too.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 0
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from ramp.recorder.reading import BadRecording, Recording

    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print("ramp log plot needs matplotlib, the `log` extra: pip install '.[log]' in a RAMP "
              "checkout", file=sys.stderr)
        return 2
    from ramp.recorder.plot import PlotData, plot

    data = PlotData()
    rec = Recording(args.files, progress=args.progress)
    try:
        for msg in rec:
            data.add(msg)
    except BadRecording as exc:
        print(f"ramp log: {exc}", file=sys.stderr)
        return 2
    title = args.title if args.title is not None else ", ".join(f.name for f in args.files)
    cut = [f for f in rec.files if f.truncated]
    if cut:
        title += " (cut short)"
    try:
        out = plot(data, args.out, title)
    except ValueError as exc:
        print(f"ramp log: {exc}", file=sys.stderr)
        return 1
    print(f"ramp log: wrote {out}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m ramp.recorder.logcli summary|plot ...` (the same as `ramp log ...`)."""
    parser = argparse.ArgumentParser(prog="ramp")
    add_log_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["log", *(sys.argv[1:] if argv is None else argv)])
    code: int = args.func(args)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
