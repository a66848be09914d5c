"""Plugins with bugs on purpose (SPEC 2.2, "Plugin code is untrusted on the safety path"): a
module type and a bus driver whose methods raise where their class's `broken` set says, as
a third-party package's would. `tests/hil_sim/test_plugin_bugs.py` registers them under
entry points of a distribution named `acme-faulty` (see `register`), names them in YAML and
drives the robot over MCP.

Each message carries a counter, as a real bug's often does (an address, a time): the
traceback must still be logged once per fault episode, not at every repeat.
"""

from __future__ import annotations

import itertools
import socket
from collections.abc import Mapping
from typing import Any, ClassVar

from ramp.api import Function, IntParam, Property, Response, Task
from ramp.hal.interfaces import DigitalOutput, MotorChannel
from ramp.hal.simio import SimBus
from ramp.modules.demo import DemoModule

DIST = "acme-faulty"
_count = itertools.count(1)


class PluginBug(RuntimeError):
    """What the faulty plugins raise: a bug, not a device error."""


def _bug(where: str) -> PluginBug:
    return PluginBug(f"{where} is broken (call {next(_count)})")


class FaultyModule(DemoModule):
    """The demo module (a motor, a lamp) with a second motion function, a property and a
    task, each of which, and each of its life-cycle methods, raises when named in
    `broken`: `init`, `start`, `is_moving`, `stop`, `vel` (after commanding its motor: the
    worst case), `pulse` (before commanding anything), `lamp`, `get` (its `motor.temp`
    property), `read` (its read function `motor.load`), `tasks`, `task`."""

    broken: ClassVar[set[str]] = set()

    def __init__(self, name: str, devices: Mapping[str, Any],
                 settings: Mapping[str, Mapping[str, Any]]) -> None:
        if "init" in self.broken:
            raise _bug("__init__")
        super().__init__(name, devices, settings)
        self.add(Function("motor", "pulse", (IntParam(-100, 100),), self._pulse, "motion",
                          "a short push in %"))
        self.prop(Property("motor", "temp", "int", self._temp, "C"))
        self.add(Function("motor", "load", (), self._load, "read", "the motor's load"))

    def _check(self, where: str) -> None:
        if where in self.broken:
            raise _bug(where)

    def _vel(self, pct: int) -> None:
        super()._vel(pct)
        self._check("vel")

    def _pulse(self, pct: int) -> None:
        self._check("pulse")
        super()._vel(pct)

    def _lamp(self, on: int) -> None:
        self._check("lamp")
        super()._lamp(on)

    def _load(self) -> list[Response]:
        self._check("read")
        return [Response(self.name, "motor", "load", (0,))]

    def _temp(self) -> int:
        self._check("get")
        return 21

    def start(self, now: float) -> None:
        self._check("start")

    def stop(self) -> None:
        self._check("stop")
        super().stop()

    def is_moving(self) -> bool:
        self._check("is_moving")
        return super().is_moving()

    def tasks(self) -> list[Task]:
        self._check("tasks")
        return [Task("watch", 10.0, self._watch)]

    def _watch(self, now: float, dt: float) -> None:
        self._check("task")


class FaultyBus(SimBus):
    """The sim driver (on the test's FakeWorld) raising, when named in `broken`, in: `init`
    (when built), `open`,
    `ready`, `waiting` (it is then never ready, so the loop asks why), `fileno`, `tick` (its
    read path), `input` (its descriptor's handler), `command` and `output` (after writing:
    the worst case), `stop_motors`, `close`. It owns a socket pair so that its input is
    watched by the loop as a serial port's is; `poke` makes it readable."""

    driver_name = "faultybus"
    broken: ClassVar[set[str]] = set()
    #: The last open instance (the test pokes its input).
    last: ClassVar[FaultyBus | None] = None

    def __init__(self, name: str, params: dict[str, Any], world: Any = None) -> None:
        if "init" in self.broken:
            raise _bug("__init__")
        super().__init__(name, params, world=world)
        self._pair: tuple[socket.socket, socket.socket] | None = None

    def _check(self, where: str) -> None:
        if where in self.broken:
            raise _bug(where)

    def _open(self, now: float) -> None:
        self._check("open")
        super()._open(now)
        self._pair = socket.socketpair()
        self._pair[0].setblocking(False)
        FaultyBus.last = self

    def poke(self) -> None:
        if self._pair is not None:  # (closed: nothing to read)
            self._pair[1].send(b"x")

    def fileno(self) -> int | None:
        self._check("fileno")
        return self._pair[0].fileno() if self._pair is not None else None

    def on_readable(self, now: float) -> None:
        assert self._pair is not None
        self._pair[0].recv(64)
        self._check("input")

    def ready(self) -> bool:
        self._check("ready")
        return self.is_open and "waiting" not in self.broken

    def waiting(self) -> str:
        self._check("waiting")
        return ""

    def _tick(self, now: float, dt: float) -> None:
        self._check("tick")
        super()._tick(now, dt)

    def _motor_changed(self, ch: MotorChannel) -> None:
        super()._motor_changed(ch)
        self._check("command")

    def _output_changed(self, ch: DigitalOutput) -> None:
        super()._output_changed(ch)
        self._check("output")

    def _stop_motors(self) -> None:
        self._check("stop_motors")
        super()._stop_motors()

    def _close(self) -> None:
        pair, self._pair = self._pair, None
        if pair is not None:
            for s in pair:
                s.close()
        self._check("close")


def register(monkeypatch: Any) -> None:
    """Register both under entry points of `acme-faulty`, beside every installed plugin."""
    import ramp.registry as registry_module
    from ramp.registry import Entry, Registry, _installed

    here = __name__
    monkeypatch.setitem(registry_module._REGISTRIES, "ramp.modules", Registry(
        "ramp.modules", [*_installed("ramp.modules"),
                         Entry("crane", f"{here}:FaultyModule", DIST)]))
    monkeypatch.setitem(registry_module._REGISTRIES, "ramp.drivers", Registry(
        "ramp.drivers", [*_installed("ramp.drivers"),
                         Entry("faultybus", f"{here}:FaultyBus", DIST)]))
