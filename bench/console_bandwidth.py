"""`console_bandwidth`: the operator console's two links during a realtime mission (SPEC 7.1).

RMC scored the operator link's average bandwidth; the console's budget is 16 kB/s for its two
links together (MCP to the robot, and the autonomy's live view) at default settings. The run:
`ramp sim mission --realtime --foxglove-port 0` (the robot, its emulators and the autonomy on
the wall clock), and `ramp-teleop --backend ... --autonomy ...` at its defaults, each link
through a counting TCP proxy of ours (bytes of TCP payload both ways; the IP/TCP headers and
the loopback's framing are not counted). No page is open: a page talks only to ramp-teleop,
and what the console asks of the robot does not depend on it.

Reported: each link's average bytes/s by direction (MCP polling and the view separately),
their sum, the busiest second, and the mission states the run went through (scans and the
plan make the view's traffic uneven). There is no baseline: the budget is the yardstick.
"""

from __future__ import annotations

import contextlib
import re
import select
import socket
import sys
import threading
import time
from pathlib import Path
from typing import Any

from bench.common import Child, Settings, progress

SECONDS = {"full": 180.0, "quick": 4.0, "smoke": 2.0}
SEED = 5
LIMIT_BPS = 16_000


class CountingProxy:
    """Forwards one listening port to a target, counting the bytes each way."""

    def __init__(self, target: tuple[str, int]) -> None:
        self.target = target
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.up = 0    # client -> target
        self.down = 0  # target -> client
        self.connections = 0
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True, name="proxy")
        self._thread.start()

    def _run(self) -> None:
        pairs: dict[socket.socket, tuple[socket.socket, bool]] = {}
        try:
            while not self._stop:
                r, _, _ = select.select([self.listener, *pairs], [], [], 0.1)
                for s in r:
                    if s is self.listener:
                        client, _ = self.listener.accept()
                        try:
                            server = socket.create_connection(self.target, timeout=2)
                        except OSError:
                            client.close()
                            continue
                        self.connections += 1
                        pairs[client] = (server, True)
                        pairs[server] = (client, False)
                        continue
                    other, upward = pairs.get(s, (None, False))
                    if other is None:
                        continue
                    try:
                        data = s.recv(65536)
                    except OSError:
                        data = b""
                    if not data:
                        for x in (s, other):
                            pairs.pop(x, None)
                            with contextlib.suppress(OSError):
                                x.close()
                        continue
                    if upward:
                        self.up += len(data)
                    else:
                        self.down += len(data)
                    with contextlib.suppress(OSError):
                        other.sendall(data)
        finally:
            for s in pairs:
                with contextlib.suppress(OSError):
                    s.close()
            self.listener.close()

    @property
    def total(self) -> int:
        return self.up + self.down

    def close(self) -> None:
        self._stop = True
        self._thread.join(2)


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    seconds = SECONDS.get(settings.profile, SECONDS["quick"])
    mission = Child("mission", [sys.executable, "-m", "ramp.cli", "sim", "mission",
                                "--realtime", "--port", "0", "--foxglove-port", "0",
                                "--seed", str(SEED), "--duration", str(int(seconds + 120))],
                    workdir)
    view_port = int(mission.expect(r".*foxglove live on ws://[\d.]+:(\d+)", 60).group(1))
    mcp_port = int(mission.expect(r".*MCP on [\d.]+:(\d+)", 30).group(1))
    mcp = CountingProxy(("127.0.0.1", mcp_port))
    view = CountingProxy(("127.0.0.1", view_port))
    teleop = Child("teleop", [sys.executable, "-m", "ramp.teleop", "--backend",
                              f"127.0.0.1:{mcp.port}", "--autonomy", f"127.0.0.1:{view.port}",
                              "--http-port", "0"], workdir)
    states: list[str] = []
    try:
        teleop.expect(r"ramp-teleop: open ", 30)
        # Connected, described, subscribed: the steady state from here.
        time.sleep(0.5 if settings.profile == "smoke" else 2.0)
        progress(f"console_bandwidth: {seconds:.0f} s of a realtime mission through "
                 "counting proxies")
        start = (time.monotonic(), mcp.up, mcp.down, view.up, view.down)
        per_second: list[float] = []
        last = (start[0], mcp.total + view.total)
        while time.monotonic() - start[0] < seconds:
            time.sleep(1.0)
            now, total = time.monotonic(), mcp.total + view.total
            per_second.append((total - last[1]) / (now - last[0]))
            last = (now, total)
            with contextlib.suppress(Exception):
                while True:  # the mission's state changes, as printed (non-blocking)
                    line = mission.read_line(0.01)
                    m = re.search(r"->\s+(\w+)", line)
                    if m:
                        states.append(m.group(1))
        t0, mu0, md0, vu0, vd0 = start
        elapsed = time.monotonic() - t0
    finally:
        teleop.terminate()
        mission.terminate(20)
        mcp.close()
        view.close()

    def bps(n: int) -> float:
        return round(n / elapsed, 1)

    mcp_up, mcp_down = mcp.up - mu0, mcp.down - md0
    view_up, view_down = view.up - vu0, view.down - vd0
    total = mcp_up + mcp_down + view_up + view_down
    return {
        "seconds": round(elapsed, 1),
        "seed": SEED,
        "limit_bps": LIMIT_BPS,
        "total_bps": bps(total),
        "within_limit": bps(total) <= LIMIT_BPS,
        "mcp": {"bps": bps(mcp_up + mcp_down), "up_bps": bps(mcp_up),
                "down_bps": bps(mcp_down), "connections": mcp.connections},
        "view": {"bps": bps(view_up + view_down), "up_bps": bps(view_up),
                 "down_bps": bps(view_down), "connections": view.connections},
        "busiest_second_bps": round(max(per_second, default=0.0), 1),
        "states": sorted(set(states)),
    }
