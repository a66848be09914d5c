"""`python -m bench`: run the benchmarks and print one JSON document on stdout.

    python -m bench                 full run (several minutes on 2 cores)
    python -m bench --quick         under two minutes
    python -m bench --only tick,startup --out bench.json

Progress goes to stderr. A benchmark that fails is reported as {"error": ...} in its section
and the others still run; the exit status is 1 when any section failed.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import tempfile
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import Any

from bench import SECTIONS
from bench.common import PROFILES, kill_all, machine_info, progress
from ramp.common.outputs import output_file


def _on_signal(signum: int, frame: FrameType | None) -> None:
    # Unwind through every `finally`, which ends our children.
    raise KeyboardInterrupt(signal.Signals(signum).name)


def parse_only(text: str | None) -> list[str]:
    if not text:
        return list(SECTIONS)
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in SECTIONS]
    if unknown:
        raise argparse.ArgumentTypeError(
            f"unknown benchmark {', '.join(unknown)}; choose from {', '.join(SECTIONS)}")
    return [n for n in SECTIONS if n in names]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--quick", action="store_true", help="short runs (under two minutes)")
    mode.add_argument("--smoke", action="store_true",
                      help="minimal settings: proves the code runs (used by the test suite)")
    parser.add_argument("--only", type=parse_only, default=None, metavar="NAME[,NAME]",
                        help=f"run only these: {', '.join(SECTIONS)}")
    parser.add_argument("--out", type=lambda text: Path(output_file(text)),
                        help="also write the JSON document to this file (checked first)")
    args = parser.parse_args(argv)
    settings = PROFILES["smoke" if args.smoke else "quick" if args.quick else "full"]
    names = args.only or list(SECTIONS)

    signal.signal(signal.SIGTERM, _on_signal)
    doc: dict[str, Any] = {
        "suite": "ramp-bench",
        "profile": settings.profile,
        "settings": settings.as_dict(),
        "machine": machine_info(),
    }
    failed = False
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="ramp-bench-") as tmp:
        try:
            for name in names:
                workdir = Path(tmp) / name
                workdir.mkdir()
                t0 = time.monotonic()
                try:
                    module = importlib.import_module(f"bench.{name}")
                    doc[name] = module.run(settings, workdir)
                except KeyboardInterrupt:
                    raise
                except Exception as exc:  # noqa: BLE001 - report it, run the others
                    failed = True
                    progress(f"{name} FAILED: {exc}")
                    doc[name] = {"error": f"{type(exc).__name__}: {exc}",
                                 "traceback": traceback.format_exc()}
                finally:
                    kill_all()
                progress(f"{name}: done in {time.monotonic() - t0:.1f} s")
        finally:
            kill_all()
    doc["machine"]["loadavg_at_end"] = [round(x, 2) for x in os.getloadavg()]
    doc["elapsed_s"] = round(time.monotonic() - started, 1)
    text = json.dumps(doc, indent=2)
    if args.out is not None:
        args.out.write_text(text + "\n")
    print(text)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
