"""When interlock rules are evaluated (SPEC 11, issue 35 item 6): a tick evaluates only the
rules that are active or have a comparison a changed reading may flip, so 480 rules over
readings that do not cross a threshold cost the reads alone; and what a rule's entries cover
and forbid."""

from __future__ import annotations

import logging
import time
from types import SimpleNamespace
from typing import Any

import pytest

from ramp.layers.module_distribution import Function, Module, Property
from ramp.layers.robot_distribution.condition import parse_condition
from ramp.layers.robot_distribution.interlocks import Interlocks, RuleSpec, covered
from ramp.mcp.params import IntParam


class Rig(Module):
    """A module of one motor and 480 sensors, read from plain attributes."""

    def __init__(self, sensors: int = 480) -> None:
        super().__init__("m")
        self.readings = [0.0] * sensors
        self.v = 0
        self.add(Function("motor", "vel", (IntParam(-100, 100),), self._vel))
        self.add(Function("m", "go", (IntParam(-100, 100),), self._vel, moves=("motor",)))
        self.prop(Property("motor", "vel", "int", lambda: self.v))
        for i in range(sensors):
            self.prop(Property(f"s{i}", "x", "float", self._reader(i)))

    def _reader(self, i: int) -> Any:
        return lambda: self.readings[i]

    def _vel(self, v: int) -> None:
        self.v = v

    def stop(self) -> None:
        self.v = 0

    def is_moving(self) -> bool:
        return self.v != 0


def rig(n_rules: int = 480, sensors: int = 480) -> tuple[Rig, Interlocks]:
    module = Rig(sensors)
    slot = SimpleNamespace(name="m", state="ok", module=module)
    specs = [RuleSpec(f"r{i}", parse_condition(f"m:s{i % sensors}.x > 10"), "refuse",
                      (("m:motor.vel", None),)) for i in range(n_rules)]
    return module, Interlocks(specs, {"m": slot})


def evaluations(ilk: Interlocks) -> int:
    return sum(r.evaluations for r in ilk.rules)


def test_rules_are_not_re_evaluated_when_nothing_they_read_changed() -> None:
    module, ilk = rig()
    ilk.tick(0.0, 0.01)
    assert evaluations(ilk) == 480  # the first tick sees every reading for the first time
    for k in range(1, 50):
        ilk.tick(k * 0.01, 0.01)
    assert evaluations(ilk) == 480  # nothing moved: nothing evaluated
    for k in range(10):  # readings wander (noise) without crossing a threshold
        module.readings[k] = 3.0 + k / 10
        ilk.tick(0.4 + k * 0.01, 0.01)
    assert evaluations(ilk) == 480  # no comparison could have changed
    module.readings[7] = 10.0  # on the threshold: `> 10` may flip, so it is asked
    ilk.tick(0.5, 0.01)
    assert evaluations(ilk) == 481 and ilk.active_names() == ()
    module.readings[7] = 20.0
    ilk.tick(0.51, 0.01)
    assert ilk.active_names() == ("r7",)
    # An active rule is evaluated every tick (its release needs the time it has been clear).
    before = evaluations(ilk)
    ilk.tick(0.52, 0.01)
    ilk.tick(0.53, 0.01)
    assert evaluations(ilk) == before + 2
    module.readings[7] = 0.0
    for k in range(20):
        ilk.tick(0.54 + k * 0.01, 0.01)
    assert ilk.active_names() == ()


def test_equality_and_unreadable_readings_are_never_skipped() -> None:
    module = Rig(2)
    slot = SimpleNamespace(name="m", state="ok", module=module)
    specs = [RuleSpec("eq", parse_condition("m:s0.x == 1"), "refuse", (("m:motor.vel", None),)),
             RuleSpec("ne", parse_condition("not m:s1.x != 0"), "refuse",
                      (("m:motor.vel", None),))]
    ilk = Interlocks(specs, {"m": slot})
    ilk.tick(0.0, 0.01)
    assert ilk.active_names() == ("ne",)  # s1 reads 0
    module.readings[0], module.readings[1] = 1.0, 0.5
    ilk.tick(0.01, 0.01)
    assert "eq" in ilk.active_names()
    for k in range(20):
        ilk.tick(0.02 + k * 0.01, 0.01)
    assert ilk.active_names() == ("eq",)
    slot.state = "fault"  # unreadable: fail closed, both
    ilk.tick(0.3, 0.01)
    assert ilk.active_names() == ("eq", "ne")


def test_a_rule_released_by_a_request_is_seen_again_by_the_next_tick() -> None:
    module, ilk = rig(n_rules=1, sensors=1)
    module.readings[0] = 20.0
    ilk.tick(0.0, 0.01)
    assert ilk.active_names() == ("r0",)
    module.readings[0] = 0.0
    vel = module.functions[("motor", "vel")]
    assert ilk.permit("m", vel, [5], 0.05) is not None  # clear, not yet for 0.1 s
    assert ilk.permit("m", vel, [5], 0.2) is None  # released by the request
    module.readings[0] = 20.0  # back to what the last tick saw: it holds again
    ilk.tick(0.21, 0.01)
    assert ilk.active_names() == ("r0",)


def test_a_rule_engages_on_the_first_tick_its_reading_changes() -> None:
    module, ilk = rig(n_rules=3, sensors=3)
    ilk.tick(0.0, 0.01)
    module.v = 50
    module.readings[2] = 11.0
    ilk.tick(0.01, 0.01)
    assert ilk.active_names() == ("r2",)
    assert module.v == 0  # a refuse stops what it covers as it engages


def test_an_idle_tick_with_480_rules_costs_the_reads_alone() -> None:
    """Not a benchmark (two shared cores): an order of magnitude, printed, with a bound far
    above what the reads cost so the test cannot flake."""
    _, ilk = rig()
    ilk.tick(0.0, 0.01)
    t0 = time.perf_counter()
    for k in range(1, 101):
        ilk.tick(k * 0.01, 0.01)
    per_tick = (time.perf_counter() - t0) / 100
    print(f"idle tick with 480 rules over 480 readings: {per_tick * 1e6:.0f} us")
    assert per_tick < 0.005


def test_a_module_level_function_is_covered_through_the_devices_it_moves() -> None:
    module, _ = rig(1, 1)
    functions, devices = covered("m:motor.vel", {"m": module})
    assert sorted(f.name for _, f in functions) == ["go", "vel"]
    assert devices == {"m": ("motor",)}
    functions, _ = covered("m:m.go", {"m": module})
    assert sorted(f.name for _, f in functions) == ["go", "vel"]


def test_one_direction_refuses_that_way_and_lets_the_other_run() -> None:
    module = Rig(1)
    slot = SimpleNamespace(name="m", state="ok", module=module)
    spec = RuleSpec("fwd", parse_condition("m:s0.x > 10"), "stop", (("m:m.go", None),),
                    directions=(1,))
    ilk = Interlocks([spec], {"m": slot})
    module.v = -30  # reversing when the rule engages: left running
    module.readings[0] = 20.0
    ilk.tick(0.0, 0.01)
    assert ilk.active_names() == ("fwd",) and module.v == -30
    vel = module.functions[("motor", "vel")]
    go = module.functions[("m", "go")]
    assert ilk.permit("m", vel, [20], 0.01) is not None
    assert ilk.permit("m", vel, [-20], 0.01) is None
    assert ilk.permit("m", vel, [0], 0.01) is None
    # `go` declares no senses and moves one device with a speed: the sign of its speed.
    assert ilk.permit("m", go, [5], 0.01) is not None
    assert ilk.permit("m", go, [-5], 0.01) is None


def test_a_limit_never_re_runs_a_stopped_module_level_request() -> None:
    module = Rig(1)
    slot = SimpleNamespace(name="m", state="ok", module=module)
    spec = RuleSpec("slow", parse_condition("m:s0.x > 10"), "limit", (("m:m.go", 10),))
    ilk = Interlocks([spec], {"m": slot})
    go = module.functions[("m", "go")]
    assert ilk.permit("m", go, [60], 0.0) is None
    go.run(60)
    ilk.ran("m", go, [60])
    module.stop()  # stopped by a path that did not tell the interlocks
    module.readings[0] = 20.0
    ilk.tick(0.01, 0.01)
    assert ilk.active_names() == ("slow",)
    assert module.v == 0


def test_a_request_evaluates_only_rules_a_changed_reading_may_flip() -> None:
    module, ilk = rig()
    ilk.tick(0.0, 0.01)
    vel = module.functions[("motor", "vel")]
    before = evaluations(ilk)
    for k in range(20):
        assert ilk.permit("m", vel, [5], 0.001 * k) is None
    assert evaluations(ilk) == before  # 480 guards, nothing changed: none evaluated
    module.readings[3] = 11.0  # between two ticks: the request still sees it
    assert ilk.permit("m", vel, [5], 0.03) is not None
    assert evaluations(ilk) == before + 1
    assert ilk.active_names() == ("r3",)


def test_an_info_rule_logs_at_debug_and_a_warning_rule_at_warning(
        caplog: pytest.LogCaptureFixture) -> None:
    module = Rig(2)
    slot = SimpleNamespace(name="m", state="ok", module=module)
    specs = [RuleSpec("shaping", parse_condition("m:s0.x > 10"), "stop",
                      (("m:motor.vel", None),), severity="info"),
             RuleSpec("alarm", parse_condition("m:s1.x > 10"), "stop",
                      (("m:motor.vel", None),))]
    ilk = Interlocks(specs, {"m": slot})
    ilk.tick(0.0, 0.01)
    module.readings[0] = module.readings[1] = 20.0
    with caplog.at_level(logging.DEBUG, logger="ramp.interlock"):
        ilk.tick(0.01, 0.01)
    levels = {r.getMessage().split()[1]: r.levelno for r in caplog.records
              if r.getMessage().startswith("interlock ")}
    assert levels == {"shaping": logging.DEBUG, "alarm": logging.WARNING}
    assert [r.activations for r in ilk.rules] == [1, 1]


def test_which_way_a_drive_turns_each_wheel() -> None:
    from ramp.modules import base, diff_base  # noqa: PLC0415

    assert base.drive_senses(40, 0) == (1, 1, 1, 1)
    assert base.drive_senses(40, 180) == base.drive_senses(-40, 0) == (-1, -1, -1, -1)
    assert base.drive_senses(40, 90) == (1, 1, -1, -1)  # a spin: one side each way
    assert base.drive_senses(40, 45) == (1, 1, 0, 0)  # a pivot on the right side
    assert base.drive_senses(30, 160) == (-1, -1, -1, -1)  # backing away, turning
    assert base.drive_senses(0, 0) == (0, 0, 0, 0)
    assert diff_base.drive_senses(30, 200) == (-1, -1)
