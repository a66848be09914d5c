"""Print this interpreter's path if RAMP's .venv can be made from it, else nothing (exit 1).

The Makefile asks the system's Python 3 first (see its comment on PYTHON): it must be 3.11 or
newer, have `venv` with `ensurepip` (Debian's python3-venv) and the C headers mypyc's build
needs (python3-dev); without them the first python3 on PATH is used instead.
"""

from __future__ import annotations

import importlib.util
import sys
import sysconfig
from pathlib import Path


def usable() -> bool:
    if sys.version_info < (3, 11):  # noqa: UP036 - run by any system Python, older ones too
        return False
    if importlib.util.find_spec("ensurepip") is None or importlib.util.find_spec("venv") is None:
        return False
    import ensurepip

    try:
        ensurepip.version()  # the pip wheel a new venv is given
    except Exception:  # noqa: BLE001 - any failure means this Python cannot make our venv
        return False
    return (Path(sysconfig.get_paths()["include"]) / "Python.h").is_file()


if __name__ == "__main__":
    if not usable():
        sys.exit(1)
    sys.stdout.write(sys.executable + "\n")
