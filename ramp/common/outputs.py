"""Files a command writes (a plot, a trace, a recording), checked before the work starts.

A plot path in a missing or read-only directory used to fail with a traceback after the whole
ten-minute mission had run. `check_output` makes the missing directories (as the recorder
does) and creates the file once, so whatever would stop the write stops the command first,
in words. `save_figure` then writes exactly the path asked for: matplotlib alone would append
`.png` to a name without a known suffix and write somewhere else than the command reports.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import stat
from pathlib import Path
from typing import Any

from ramp.common.files import FileProblem, kind


class OutputError(FileProblem):
    """The path cannot be written."""


def check_output(path: str | Path) -> Path:
    """The path, once a file can be created (or overwritten) there; OutputError otherwise
    (`cannot write PATH: why`).

    Missing directories are made. A file that did not exist is removed again, so a command
    that fails later leaves no empty plot behind. Never waits: a FIFO is refused, not
    opened."""
    text = str(path)
    if not text.strip():
        raise OutputError("expected a file name")
    p = Path(text)
    try:
        info = p.stat()
    except FileNotFoundError:
        info = None
    except OSError as exc:
        raise OutputError(f"cannot write {text}: {exc.strerror or exc}") from None
    if info is not None and (stat.S_ISDIR(info.st_mode) or stat.S_ISFIFO(info.st_mode)
                             or stat.S_ISSOCK(info.st_mode)):
        raise OutputError(f"cannot write {text}: {kind(info.st_mode)}; expected a file")
    flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        os.close(os.open(p, flags, 0o666))
    except OSError as exc:
        raise OutputError(f"cannot write {text}: {exc.strerror or exc}") from None
    if info is None:
        p.unlink(missing_ok=True)
    return p


def save_figure(fig: Any, path: str | Path, **savefig: Any) -> Path:
    """`fig.savefig` to exactly `path`: the format from its suffix when matplotlib knows it,
    PNG otherwise; missing directories are made."""
    p = Path(path)
    suffix = p.suffix[1:].lower()
    fmt = suffix if suffix in fig.canvas.get_supported_filetypes() else "png"
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p, format=fmt, **savefig)
    return p


def output_file(text: str) -> str:
    """argparse `type=` for an option naming a file to write: checked (`check_output`) as the
    command line is read, so a bad path is a usage error before any work is done."""
    try:
        check_output(text)
    except OutputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def figure_path(text: str) -> str:
    """A picture's file name as written: `.png` added to a name without a suffix, so
    `--plot scan` (or a directory's name) writes `scan.png` and the command says so."""
    return text if Path(text).suffix else text + ".png"


def figure_file(text: str) -> str:
    """argparse `type=` for an option naming a picture to write: `figure_path`, checked as
    `output_file` checks it."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a file name")
    return output_file(figure_path(text))


PLOT_NEEDS_MATPLOTLIB = "--plot needs matplotlib: pip install 'ramp[plot]'"


def plot_unavailable(plot: str | None) -> str | None:
    """What to say, before any work, about a `--plot` that could not be drawn (matplotlib is
    an optional extra); None when there is no picture asked for or it can be drawn."""
    if plot and importlib.util.find_spec("matplotlib") is None:
        return PLOT_NEEDS_MATPLOTLIB
    return None
