"""`ramp fleet sim`: a whole fleet on this machine (SPEC 14, what `make fleet` runs).

A plain Mosquitto on loopback (its own local-only mode; `ramp fleet init` makes the TLS
set-up), then per robot its backend and its agent, each a process of its own (a killed agent
is a crash the others survive, and the broker reports it by its last will), then the page.
Robot kinds: `marte` (the simulated RMC mission on the wall clock, with the autonomy, which
waits for the fleet's `rmcMission`), `marte-noauto` (MARTE's backend alone), `scout`.
`--consoles` adds an operator console (`ramp-teleop`) per robot, linked from its tile.
Ctrl-C (or SIGTERM) stops the robots first, so every motor is stopped, then the rest.
"""

from __future__ import annotations

import argparse
import os
import re
import select
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from ramp.fleet.broker import LocalBroker

ROOT = Path(__file__).resolve().parents[2]
KINDS = {
    "marte": ["sim", "mission", "--realtime", "--port", "0", "--command-port", "0"],
    "marte-noauto": ["run", "--sim", "--config", str(ROOT / "ramp.yaml"), "--port", "0"],
    "scout": ["run", "--sim", "--config", str(ROOT / "examples" / "robots" / "scout.yaml"),
              "--port", "0"],
}
CONFIGS = {"marte": ROOT / "ramp.yaml", "marte-noauto": ROOT / "ramp.yaml",
           "scout": ROOT / "examples" / "robots" / "scout.yaml"}


@dataclass
class Proc:
    """A child process whose stdout is searched for the lines it announces itself with."""

    name: str
    popen: subprocess.Popen[bytes]
    lines: list[str] = field(default_factory=list)
    buf: str = ""

    def expect(self, pattern: str, timeout: float = 60.0) -> re.Match[str]:
        assert self.popen.stdout is not None
        fd = self.popen.stdout.fileno()
        deadline = time.monotonic() + timeout
        while True:
            while "\n" in self.buf:
                line, self.buf = self.buf.split("\n", 1)
                self.lines.append(line)
                m = re.search(pattern, line)
                if m:
                    return m
            if time.monotonic() >= deadline or self.popen.poll() is not None:
                raise RuntimeError(f"{self.name} never said {pattern!r}: "
                                   + " | ".join(self.lines[-5:]))
            r, _, _ = select.select([fd], [], [], 0.2)
            if r:
                data = os.read(fd, 65536)
                if data:
                    self.buf += data.decode(errors="replace")

    def stop(self, timeout: float = 10.0) -> None:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(5)


def _spawn(name: str, args: list[str], log: Path) -> Proc:
    err = open(log, "ab")  # noqa: SIM115 (the child's stderr, closed below)
    try:
        popen = subprocess.Popen([sys.executable, *args], cwd=ROOT, stdout=subprocess.PIPE,
                                 stderr=err, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    finally:
        err.close()
    return Proc(name, popen)


def add_sim(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("sim", help="a simulated fleet: a local broker, robots, agents, page",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robots", default="marte,marte-noauto,scout",
                   help=f"comma-separated kinds ({', '.join(KINDS)}); default all three")
    p.add_argument("--broker-port", type=int, default=0, help="the broker's port (0: free)")
    p.add_argument("--http-port", type=int, default=8090, help="the page's port (default 8090)")
    p.add_argument("--consoles", action="store_true",
                   help="also an operator console (ramp-teleop) per robot, linked from its tile")
    p.set_defaults(func=cmd_sim)


def cmd_sim(args: argparse.Namespace) -> int:
    kinds = [k.strip() for k in args.robots.split(",") if k.strip()]
    unknown = [k for k in kinds if k not in KINDS]
    if unknown or not kinds:
        print(f"ramp fleet sim: --robots: unknown {', '.join(unknown) or '(none given)'}; "
              f"choose from {', '.join(KINDS)}", file=sys.stderr)
        return 2
    work = Path(tempfile.mkdtemp(prefix="ramp-fleet-sim-"))
    stopping: list[int] = []
    signal.signal(signal.SIGTERM, lambda s, f: stopping.append(s))
    broker = LocalBroker(port=args.broker_port)
    robots: list[Proc] = []
    others: list[Proc] = []
    try:
        broker.start()
        print(f"ramp fleet: broker on {broker.address}", flush=True)
        consoles: list[str] = []  # the page's --console SERIAL=URL arguments
        seen: dict[str, int] = {}
        for kind in kinds:
            seen[kind] = seen.get(kind, 0) + 1
            serial = f"{kind}-{seen[kind]}"
            # each robot keeps its latches apart (two MARTEs share one config file)
            keep = ["--state-dir", str(work / serial)] if KINDS[kind][0] == "run" else []
            robot = _spawn(f"robot {serial}", ["-m", "ramp.cli", *KINDS[kind], *keep],
                           work / f"{serial}.log")
            robots.append(robot)
            m = robot.expect(r"(?:MCP|ready) on ([\d.]+):(\d+)")
            mcp = f"{m.group(1)}:{m.group(2)}"
            agent_args = ["-m", "ramp.fleet.cli", "--config", str(CONFIGS[kind]), "--backend",
                          mcp, "--broker", broker.address, "--serial", serial,
                          "--state-dir", str(work)]
            if kind == "marte":
                m = robot.expect(r"autonomy commands on ([\d.]+):(\d+)")
                agent_args += ["--autonomy", f"{m.group(1)}:{m.group(2)}"]
            agent = _spawn(f"agent {serial}", agent_args, work / f"agent-{serial}.log")
            others.append(agent)
            agent.expect(r"ramp-fleet-agent: ")
            print(f"ramp fleet: robot {serial} ({kind}) MCP on {mcp}", flush=True)
            if args.consoles:
                console = _spawn(f"console {serial}", ["-m", "ramp.teleop.cli", "--backend", mcp,
                                                       "--http-port", "0"],
                                 work / f"console-{serial}.log")
                others.append(console)
                url = console.expect(r"open (http://\S+)").group(1)
                print(f"ramp fleet: console for {serial} on {url}", flush=True)
                consoles += ["--console", f"{serial}={url}"]
        page = _spawn("page", ["-m", "ramp.fleet.page.cli", "--broker", broker.address,
                               "--http-port", str(args.http_port), *consoles],
                      work / "page.log")
        others.append(page)
        m = page.expect(r"page on (http://\S+)")
        print(f"ramp fleet: page on {m.group(1)} (logs in {work}); Ctrl-C stops all",
              flush=True)
        while not stopping:
            dead = [p for p in robots + others if p.popen.poll() is not None]
            for p in dead:  # a crashed agent is the fleet's business: say so, carry on
                print(f"ramp fleet: {p.name} exited ({p.popen.returncode})", flush=True)
                (robots if p in robots else others).remove(p)
            time.sleep(0.2)  # a supervisor of processes, no control work: it only watches
    except KeyboardInterrupt:
        pass
    except RuntimeError as exc:
        print(f"ramp fleet sim: {exc}", file=sys.stderr)
        return 1
    finally:
        for p in robots:  # motors first
            p.stop()
        for p in others:
            p.stop()
        broker.close()
    print("ramp fleet: stopped (robots first: every motor at zero)", flush=True)
    return 0
