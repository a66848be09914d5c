"""The latched-fault mechanism is general (SPEC 2.2): any module declares a device's latch and
gets `DEVICE.reset=()`, a get row and the refusal of that device's motion for free."""

from __future__ import annotations

import pytest

from ramp.errors import RequestError
from ramp.layers.functional import FaultLatch
from ramp.layers.module_distribution import Function, Module, Property
from ramp.mcp.messages import Request, Response
from ramp.mcp.params import IntParam


class Winch(Module):
    """A plugin-like module: a winch whose overload latches; `winch.drive` uses the drum."""

    def __init__(self) -> None:
        super().__init__("winch")
        self.speed = 0
        self.overload = FaultLatch("drum")
        self.add(Function("drum", "vel", (IntParam(-100, 100),), self._vel, "motion"))
        self.add(Function("winch", "haul", (), lambda: self._vel(100), "motion"))
        self.add(Function("hook", "vel", (IntParam(-100, 100),), self._vel, "motion"))
        self.prop(Property("drum", "vel", "int", lambda: self.speed))
        self.latched("drum", self.overload, "overloaded", guards=("winch",))

    def _vel(self, v: int) -> None:
        self.speed = v

    def stop(self) -> None:
        self.speed = 0

    def is_moving(self) -> bool:
        return self.speed != 0


def call(m: Module, device: str, function: str, *params: str) -> list[Response] | None:
    fn, values = m.lookup(Request(m.name, device, function, params))
    return fn.run(*values)


def row(m: Module, key: str) -> object:
    got = call(m, m.name, "get") or []
    return {f"{r.device}.{r.prop}": r.values[0] for r in got}[key]


def test_a_declared_latch_gives_reset_a_row_and_refusals() -> None:
    m = Winch()
    desc = call(m, "winch", "describe") or []
    assert Response("winch", "drum", "function", ("reset",)) in desc
    assert Response("winch", "drum", "kind", ("reset", "state")) in desc
    assert Response("winch", "drum", "property", ("overloaded", "int")) in desc
    assert row(m, "drum.overloaded") == 0
    call(m, "drum", "vel", "40")
    m.overload.trip("drum overloaded: 312 N over 300 N")
    m.stop()
    assert row(m, "drum.overloaded") == 1
    for device, function, params in (("drum", "vel", ("10",)), ("winch", "haul", ())):
        with pytest.raises(RequestError) as e:
            call(m, device, function, *params)
        assert e.value.code == "fault"
        assert e.value.detail == ("drum overloaded: 312 N over 300 N; acknowledge it with "
                                  "winch:drum.reset")
    assert m.speed == 0
    call(m, "hook", "vel", "20")  # another device is not affected
    assert m.speed == 20
    call(m, "winch", "stop")  # no stop clears it
    assert row(m, "drum.overloaded") == 1
    assert call(m, "drum", "reset") is None
    assert row(m, "drum.overloaded") == 0
    call(m, "drum", "vel", "10")
    assert m.speed == 10


def test_the_first_reason_is_kept_and_logged(caplog: pytest.LogCaptureFixture) -> None:
    latch = FaultLatch("x:y")
    latch.trip("first")
    latch.trip("second")
    assert latch.reason == "first"
    latch.clear("10.0.0.2:5000")
    assert not latch.latched
    assert "x:y fault latched: first" in caplog.text
    assert "x:y fault reset by 10.0.0.2:5000 (was: first)" in caplog.text
