"""The realtime mission's backend: a process of its own, run exactly as `ramp run` runs.

In `ramp sim mission --realtime` the simulated hardware (the world's physics, the
Sabertooth emulators behind their ptys, the Hokuyo, IMU and gimbal emulators) runs in the
simulator's process (`ramp.simulation.arena_process`), and the backend here, in a process
that process starts: the supervisor built from the robot's YAML, started and run by
`ramp.runtime.service.serve` -- the stop signals, the service's SCHED_FIFO priority where
permitted, the stall guard's thread, `gc.freeze()` -- so its tick figures are the robot's.

The two speak over the wires the real hardware uses where a wire can cross a process:
each Sabertooth bus's real driver opens the pty the simulator's emulator reads, as it would
open `/dev/ttyUSB0`. The Phidget boards cannot be emulated at the wire (USB, the vendor's
library: `ramp.hal.simio`), so their HAL-level sim driver runs here on `RemoteSignals`,
whose input values the simulator sends over the **hardware link** (a socketpair serviced as
a reader on each side's loop, `ramp.autonomy.hal.simlink.SensorLink`'s framing) when they
change, and whose outputs (LEDs, motors on a Phidget board) go back over it. The `sim`
module (SPEC 12) is served here, with the robot's requests, and forwards what it injects
(`sim:bus.unplug`, `sim:input.set`, `sim:lift.jam`, `sim:lidar.blind`, `sim:imu.shift`) to
the simulator over the same link.

Messages, simulator -> backend: `in` (changed input values by label, and which HAL-level
buses are present), `stop`. Backend -> simulator: `ready` (the MCP address, the pid, what
`serve` set up), `out` (an output or motor of a HAL-level bus), `sim` (an injection),
`end` (the backend's tick figures, `TickLog.report`) once it has stopped every motor.

    python -m ramp.simulation.backend_process --link-fd N --spec JSON   (the simulator runs it)
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import socket
import sys
import time
from collections.abc import Sequence
from typing import Any

from ramp.autonomy.hal.simlink import Message, SensorLink

log = logging.getLogger("ramp.sim.backend")

#: After `end`, how long the backend waits for the simulator to close the link.
LINGER_S = 2.0
#: HAL kinds whose value the simulator sends (what a module reads of a HAL-level bus), and
#: the `SimWorld` method that reads each.
INPUT_READS = {"analog_in": "read_analog", "digital_in": "read_digital",
               "bridge_in": "read_bridge", "servo": "read_servo"}


class RemoteSignals:
    """The `SimWorld` of the HAL-level buses, in the backend's process: inputs as the
    simulator last sent them, outputs sent to it when they change."""

    def __init__(self, link: SensorLink, values: dict[str, Any],
                 present: dict[str, bool]) -> None:
        self.link = link
        self.values = dict(values)
        self.present = dict(present)
        self.revision = 0
        #: `sim:input.set` overrides, mirrored for the `sim` module's count.
        self.overrides: dict[str, float] = {}
        self._sent: dict[tuple[str, str], Any] = {}
        link.on("in", self._in)

    def _in(self, msg: Message) -> None:
        values, present = msg.get("v", {}), msg.get("present", {})
        if isinstance(values, dict):
            self.values.update(values)
        if isinstance(present, dict):
            self.present.update({str(k): bool(v) for k, v in present.items()})
        self.revision += 1

    def _send(self, op: str, label: str, *args: Any) -> None:
        if self._sent.get((op, label)) != args:
            self._sent[(op, label)] = args
            self.link.send("out", op=op, label=label, args=list(args))

    # -- SimWorld ---------------------------------------------------------------------------
    def set_motor(self, name: str, duty: float) -> None:
        self._send("set_motor", name, duty)

    def write_digital(self, name: str, on: bool) -> None:
        self._send("write_digital", name, bool(on))

    def set_servo(self, name: str, target_deg: float | None, speed_dps: float) -> None:
        self._send("set_servo", name, target_deg, speed_dps)

    def read_analog(self, name: str) -> float:
        return float(self.values.get(name, 0.0))

    def read_bridge(self, name: str) -> float:
        return float(self.values.get(name, 0.0))

    def read_servo(self, name: str) -> float:
        return float(self.values.get(name, 0.0))

    def read_digital(self, name: str) -> bool:
        return bool(self.values.get(name, False))

    def bus_present(self, bus: str) -> bool:
        return self.present.get(bus, True)

    # -- the `sim` module's hooks -------------------------------------------------------------
    def set_input(self, name: str, quantity: float) -> None:
        self.overrides[name] = quantity
        self.link.send("sim", op="input.set", args=[name, quantity])

    def clear_input(self, name: str) -> None:
        self.overrides.pop(name, None)
        self.link.send("sim", op="input.clear", args=[name])


class RemoteWorld:
    """What the `sim` module reaches of the world: `jam_lift`, sent to the simulator."""

    def __init__(self, link: SensorLink) -> None:
        self.link = link

    def jam_lift(self, on: bool) -> None:
        self.link.send("sim", op="lift.jam", args=[bool(on)])


class RemoteBackplane:
    """The `sim` module's backplane (`ramp.simulation.sim_module.SimModule`), in the
    backend's process: every hook a message to the simulator, which owns the hardware."""

    def __init__(self, config: Any, link: SensorLink, signals: RemoteSignals,
                 can_jam: bool) -> None:
        self.config = config
        self.link = link
        self.signals = signals
        self.unplugged: set[str] = set()
        self.world: Any = RemoteWorld(link) if can_jam else object()

    def unplug(self, bus: str) -> None:
        self.link.send("sim", op="bus.unplug", args=[bus])
        self.unplugged.add(bus)

    def plug(self, bus: str) -> None:
        self.link.send("sim", op="bus.plug", args=[bus])
        self.unplugged.discard(bus)


def run(spec: dict[str, Any], link: SensorLink) -> int:
    """Build the backend from `spec` (the simulator's: the config file, the port, each
    wire-level bus's params, the HAL-level inputs' first values) and serve until the
    simulator says `stop`, the link closes or a stop signal comes."""
    from ramp.clock import MonotonicClock
    from ramp.config import BusConfig
    from ramp.hal import driver_class
    from ramp.hal.simio import SimBus
    from ramp.runtime import build
    from ramp.runtime.service import SERVICE_RT_PRIORITY, ServiceState, serve
    from ramp.simulation.arena_process import TickLog
    from ramp.simulation.backend import load_backend_config
    from ramp.simulation.sim_module import SimModule

    config = load_backend_config(spec["config"])
    wire: dict[str, dict[str, Any]] = spec["wire"]
    signals = RemoteSignals(link, spec["values"], spec["present"])

    def bus_factory(bc: BusConfig) -> Any:
        if bc.name in wire:  # the real driver on the simulator's emulated wire
            return driver_class(bc.driver)(bc.name, {**bc.params, **wire[bc.name]})
        return SimBus(bc.name, dict(bc.params), world=signals)

    sup = build(config, MonotonicClock(), bus_factory, host="127.0.0.1",
                port=int(spec.get("port", 0)))
    backplane = RemoteBackplane(config, link, signals, bool(spec.get("can_jam")))
    sim = SimModule(backplane)  # type: ignore[arg-type]

    def blind(on: bool) -> None:
        link.send("sim", op="lidar.blind", args=[bool(on)])

    def shift(deg: float) -> None:
        link.send("sim", op="imu.shift", args=[float(deg)])

    sim.add_sensor_faults(blind, shift)
    sup.robot.add_extra(sim)
    ticks = TickLog(sup.scheduler)
    stopping: list[str] = []
    link.on("stop", lambda m: stopping.append("the simulator asked"))
    link.on_close.append(lambda why: stopping.append(f"the hardware link closed: {why}"))
    link.attach(sup.scheduler)

    def ready(state: ServiceState) -> None:
        host, port = sup.server.address
        link.send("ready", pid=os.getpid(), mcp=[str(host), int(port)],
                  service={"policy": state.policy, "stall_guard": state.stall_guard,
                           "gc_frozen": state.gc_frozen,
                           "stall_limit_s": sup.stall_guard.limit})

    priority = spec.get("rt_priority", SERVICE_RT_PRIORITY)  # null: the default priority

    def failed(exc: Exception) -> None:
        link.send("failed", error=f"{type(exc).__name__}: {exc}")

    code = serve(sup, ready=ready, until=lambda: bool(stopping), rt_priority=priority,
                 on_start_failed=failed)
    # Every motor has been stopped (zeros on every wire): the figures, then the end.
    if link.connected and code == 0:
        link.send("end", why=stopping[0] if stopping else "a stop signal",
                  backend=ticks.report(), stall_guard_stalls=sup.stall_guard.stalls)
    linger(link)
    link.close()
    return code


def linger(link: SensorLink) -> None:
    """What was sent leaves, then the simulator closes its end (it does once it has `end`
    or `failed`): closing first, with its messages unread here, would reset the socket and
    could lose the last message on its side."""
    link.drain(2.0)
    deadline = time.monotonic() + LINGER_S
    while link.connected and time.monotonic() < deadline:
        link.pump(0.05)


def main(argv: Sequence[str] | None = None) -> int:
    """The backend process's entry point (the simulator's process runs it)."""
    parser = argparse.ArgumentParser(prog="python -m ramp.simulation.backend_process")
    parser.add_argument("--link-fd", type=int, required=True)
    parser.add_argument("--spec", required=True, help="what to build, as JSON")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")
    link = SensorLink(socket.socket(fileno=args.link_fd), name="hardware link (backend)")
    try:
        return run(json.loads(args.spec), link)
    except Exception as exc:  # noqa: BLE001 - said to the simulator, which reports it
        log.exception("the backend could not start")
        link.send("failed", error=f"{type(exc).__name__}: {exc}")
        linger(link)
        link.close()
        return 1


if __name__ == "__main__":
    sys.exit(main())
