"""Compile the simulator's hot path with mypyc into build/accel/ (see ramp/common/accel.py).

Run by `make` after the editable install; `python scripts/build_accel.py` by hand. mypyc turns
type-annotated modules into C extensions that compute the same thing faster; the list below
is what a simulated mission spends its time in (profile: docs/developing/benchmarks-mission.md).
A module joins the list only if its tests pass compiled and mission summaries stay bit for bit
the same. Without a C compiler the build fails and RAMP runs the sources, only slower.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
from importlib.machinery import EXTENSION_SUFFIXES as _SUFFIXES
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "build" / "accel"
WORK = ROOT / "build" / "accel-work"
GROUP = "ramp_accel"
EXTENSION_SUFFIXES = tuple(_SUFFIXES)

#: The compiled modules, by path from the repository root. Left out, and why (a compiled class
#: is fixed: its methods cannot be replaced on an instance nor its base be an interpreted
#: class): the plugin API's base classes (ramp/hal/interfaces.py, ramp/autonomy/hal/
#: interfaces.py: a team's driver subclasses them in Python) and the drivers built on them in
#: Python (ramp/autonomy/hal/sim.py, simlink.py); the Hokuyo driver and the MCP link (their
#: abstract bases fail at construction); ramp/mcp/session.py (generic classes);
#: ramp/simulation/rig.py (finds files by `__file__`); RobotDistribution (tests replace its
#: `request`); ramp/hal/simio.py (its inputs redefine `value` with other types); the codecs
#: and parsers that check their arguments themselves (ramp/hal/sabertooth_codec.py,
#: ramp/autonomy/hal/scip.py, ramp/mcp/protocol.py: compiled, a bool or a memoryview is
#: converted or refused by the annotation before their own check), the planner's grid search
#: (ramp/autonomy/planning/astar.py: compiled, it was 1.7x faster but refused a cell of numpy
#: integers and a blocked map that is not bool, which its sources take) and the pose tracker
#: (tests hand it duck-typed gyros).
MODULES = [
    "ramp/scheduler.py",
    "firmware_like/imu.py",
    "firmware_like/marte.py",
    "firmware_like/arena_floor.py",
    "firmware_like/servo.py",
    "ramp/autonomy/perception/ahrs.py",
    "ramp/autonomy/perception/gimbal.py",
    "ramp/autonomy/odometry.py",
    "ramp/autonomy/mount.py",
    "firmware_like/sabertooth.py",
    "firmware_like/hokuyo.py",
    "firmware_like/pty_link.py",
    "firmware_like/bucket_ladder.py",
    "firmware_like/world.py",
    "ramp/simulation/backplane.py",
    "ramp/hal/sabertooth.py",
    "ramp/runtime/buses.py",
    "ramp/layers/robot_distribution/interlocks.py",
    "ramp/common/tcpclient.py",
    "ramp/autonomy/perception/scans.py",
    "ramp/autonomy/executive/drive.py",
    "ramp/autonomy/executive/robot.py",
    "ramp/autonomy/planning/follower.py",
    "ramp/autonomy/planning/geometry.py",
    "ramp/layers/server/tcp.py",
    "ramp/layers/functional/base_drive.py",
]


def module_name(path: str) -> str:
    return path.removesuffix(".py").replace("/", ".")


def main() -> int:
    if sys.argv[1:] == ["--list"]:  # the Makefile's dependencies
        sys.stdout.write(" ".join(MODULES) + "\n")
        return 0
    from mypyc.build import mypycify  # the dev extra's mypy ships mypyc
    from setuptools import setup

    os.chdir(ROOT)  # mypyc names the modules by their paths from here
    shutil.rmtree(OUT, ignore_errors=True)
    shutil.rmtree(WORK, ignore_errors=True)
    # Hashed before compiling: a source edited during the build no longer matches the manifest.
    sources = {p: hashlib.sha256((ROOT / p).read_bytes()).hexdigest() for p in MODULES}
    extensions = mypycify(MODULES, opt_level="3", group_name=GROUP, multi_file=True,
                          target_dir=str(WORK / "c"))
    setup(name="ramp-accel", ext_modules=extensions, script_name="build_accel.py",
          script_args=["-q", "build_ext", "--build-lib", str(OUT),
                       "--build-temp", str(WORK / "obj"), "--parallel", str(os.cpu_count() or 1)])
    built = [p.relative_to(OUT).as_posix() for p in OUT.rglob("*") if p.is_file()]

    def extension_of(name: str) -> str:
        stem = name.replace(".", "/") + "."
        for rel in built:
            if rel.startswith(stem) and rel.endswith(EXTENSION_SUFFIXES):
                return rel
        raise SystemExit(f"build_accel: no extension was built for {name}")

    manifest = {
        "cache_tag": sys.implementation.cache_tag,
        "modules": {module_name(p): {"source": p, "sha256": sources[p],
                                     "extension": extension_of(module_name(p))}
                    for p in MODULES},
        "runtime": {f"{GROUP}__mypyc": extension_of(f"{GROUP}__mypyc")},
    }
    (OUT / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    sys.stdout.write(f"build_accel: {len(MODULES)} modules compiled into {OUT.relative_to(ROOT)}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
