"""`fleet`: Stop all through a real Mosquitto to N robots (SPEC 14).

N lightweight simulated agents (default 100; a child process of their own, one paho client
each, as N robots' agents would be N processes) speak VDA 5050 at their standard rates:
`connection` (retained, with the last will), `visualization` at 2 Hz, `state` every 30 s and
on change. Each answers `stopPause` the way the real agent does: motion stopped, then a
`state` with the action FINISHED and `driving=false`. They are lightweight in that the robot
behind them is a flag, not a backend: what is measured is the fleet layer (page, broker,
agents), not the robot's own stop, which `watchdog_to_wire` and `command_to_wire` measure.

The supervisor is the page's own `FleetSupervisor`: Stop all is its `stop_all()`, and each
robot's time is from that publish to the first `state` reporting the action and
`driving=false`, as the page shows it. Repeated `fleet_rounds` times; the broker's CPU over
the run comes from /proc.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from bench.common import Settings, progress, summary

STATE_EVERY_S = 30.0
VIZ_HZ = 2.0


def agents_main(n: int, host: str, port: int) -> None:
    """The child: N simulated agents until stdin closes."""
    import threading

    import paho.mqtt.client as mqtt

    from ramp.fleet import vda5050 as v

    class Agent:
        def __init__(self, i: int) -> None:
            self.h = v.Headers("BENCH", f"robot-{i:04d}")
            self.driving, self.paused, self.actions = True, False, []
            self.lock = threading.Lock()
            self.c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=self.h.serial,
                                 protocol=mqtt.MQTTv311)
            self.c.will_set(self.h.topic("connection"),
                            json.dumps(v.connection(self.h, v.CONNECTIONBROKEN)), 1, True)
            self.c.on_connect = self.on_connect
            self.c.on_message = self.on_message
            self.c.connect(host, port, keepalive=30)
            self.c.loop_start()

        def on_connect(self, c: Any, *_: Any) -> None:
            c.subscribe(self.h.topic("instantActions"), 1)
            c.publish(self.h.topic("connection"),
                      json.dumps(v.connection(self.h, v.ONLINE)), 1, True)
            self.publish_state()

        def publish_state(self) -> None:
            f = v.StateFields()
            with self.lock:
                f.driving, f.paused = self.driving, self.paused
                f.action_states = list(self.actions)
            f.operating_mode = "AUTOMATIC"
            f.battery_state = v.battery(80.0)
            self.c.publish(self.h.topic("state"), json.dumps(v.state(self.h, f)), 0)

        def on_message(self, c: Any, _u: Any, msg: Any) -> None:
            for a in v.parse_instant_actions(v.decode(msg.payload)):
                if a.action_type == "stopPause":
                    with self.lock:
                        self.driving, self.paused = False, True
                        self.actions = [v.action_state(a.action_id, a.action_type, "FINISHED")]
                    self.publish_state()

        def visualize(self) -> None:
            self.c.publish(self.h.topic("visualization"), json.dumps(v.visualization(
                self.h, v.position(1.0, 2.0, 0.0))), 0)

    agents = [Agent(i) for i in range(n)]
    print("ready", flush=True)
    stop = threading.Event()

    def rates() -> None:
        next_state = time.monotonic() + STATE_EVERY_S
        while not stop.wait(1.0 / VIZ_HZ):
            for a in agents:
                a.visualize()
            if time.monotonic() >= next_state:
                next_state += STATE_EVERY_S
                for a in agents:
                    a.publish_state()

    threading.Thread(target=rates, daemon=True).start()
    for line in sys.stdin:
        if line.strip() == "drive":  # back to driving for the next round
            for a in agents:
                with a.lock:
                    a.driving, a.paused, a.actions = True, False, []
                a.publish_state()
            print("driving", flush=True)
    stop.set()


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run(settings: Settings, workdir: Path) -> dict[str, Any]:
    from ramp.fleet.broker import LocalBroker
    from ramp.fleet.page.supervisor import FleetSupervisor

    n = 100 if settings.profile == "full" else 30 if settings.profile == "quick" else 5
    rounds = 5 if settings.profile == "full" else 2
    with LocalBroker() as broker:
        assert broker.proc is not None
        cpu0, t0 = _cpu_s(broker.proc.pid), time.monotonic()
        sup = FleetSupervisor(broker.host, broker.port, client_id="bench-supervisor")
        sup.start()
        child = subprocess.Popen([sys.executable, "-m", "bench.fleet", str(n), broker.host,
                                  str(broker.port)], stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, text=True)
        assert child.stdin is not None and child.stdout is not None
        try:
            progress(f"fleet: {n} simulated agents on a local mosquitto")
            assert child.stdout.readline().strip() == "ready"
            deadline = time.monotonic() + 60
            while len(sup.snapshot()["robots"]) < n and time.monotonic() < deadline:
                time.sleep(0.1)
            times: list[float] = []
            per_round = []
            for r in range(rounds):
                time.sleep(1.0)  # visualization traffic flowing meanwhile
                progress(f"fleet: round {r + 1}/{rounds}: Stop all")
                sup.stop_all()
                deadline = time.monotonic() + 10
                while time.monotonic() < deadline:
                    tiles = sup.snapshot()["robots"]
                    if all(t["stop_ms"] is not None for t in tiles):
                        break
                    time.sleep(0.01)
                got = [t["stop_ms"] for t in sup.snapshot()["robots"] if t["stop_ms"] is not None]
                per_round.append({"stopped": len(got), "max_ms": max(got, default=None)})
                times += got
                child.stdin.write("drive\n")
                child.stdin.flush()
                child.stdout.readline()
            cpu1, t1 = _cpu_s(broker.proc.pid), time.monotonic()
        finally:
            child.stdin.close()
            child.wait(10)
            sup.close()
    return {"robots": n, "rounds": rounds, "per_round": per_round,
            "stop_all_to_driving_false_ms": summary(times, 1),
            "broker_cpu_pct": round(100 * (cpu1 - cpu0) / (t1 - t0), 1),
            "rates": {"visualization_hz": VIZ_HZ, "state_every_s": STATE_EVERY_S}}


if __name__ == "__main__":
    agents_main(int(sys.argv[1]), sys.argv[2], int(sys.argv[3]))
