"""Plugin code is untrusted on the safety path (SPEC 2.2; issue 33 item 1): a module plugin
and a driver plugin, registered under entry points of their own distribution
(`tests/hil_sim/faulty_plugins.py`), with each of their methods raising in turn, beside
healthy modules, over MCP on emulated hardware. Every case ends the same way: nothing moves
that should not (read on the emulated wire), the faulty module is in `fault` (or, when it
never started, not attached) with a reason, its traceback was logged once however often the
bug repeats, the other module still answers and moves, and the server still serves."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from ramp.config import BusConfig
from ramp.hal import driver_class
from ramp.hal.interfaces import Bus
from tests.harness import DEMO_YAML, FakeWorld, Harness, value
from tests.harness import TestClient as Client
from tests.hil_sim.faulty_plugins import DIST, FaultyBus, FaultyModule, register

#: The harness's demo robot with a `crane` of the faulty type in the first module's place.
MODULE_YAML = DEMO_YAML.replace("  demo: {motor:", "  crane: {type: crane, motor:")

DRIVER_YAML = """
server: {host: 127.0.0.1, port: 0, max_clients: 4}
watchdog: {timeout: 0.5}
buses:
  bad: {driver: faultybus}
  io: {driver: sim}
modules:
  winch: {type: demo, motor: {bus: bad}, lamp: {bus: bad}}
  arm: {type: demo, motor: {bus: io}, lamp: {bus: io}}
"""


@pytest.fixture(autouse=True)
def plugins(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    register(monkeypatch)
    FaultyModule.broken = set()
    FaultyBus.broken = set()
    yield
    FaultyModule.broken = set()
    FaultyBus.broken = set()


def harness(yaml_text: str) -> Harness:
    world = FakeWorld()

    def factory(bc: BusConfig) -> Bus:
        return driver_class(bc.driver)(bc.name, dict(bc.params),  # type: ignore[call-arg]
                                       world=world)

    h = Harness(yaml_text, world=world, bus_factory=factory)
    h.sup.settle()
    return h


def tracebacks(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records
            if r.exc_info is not None and r.levelno >= logging.ERROR]


def keep_talking(h: Harness, c: Client, seconds: float) -> str:
    """Heartbeats every 0.1 s (the watchdog wants them while `arm` moves); the last
    `robot.get`."""
    get = ""
    for _ in range(round(seconds / 0.1)):
        h.advance(0.1)
        get = c.ask("robot:robot.get=()")
    return get


def others_serve(h: Harness, c: Client, bad: str, healthy: str = "arm") -> None:
    """The healthy module answers and moves, the faulty one is refused, the server serves."""
    assert c.ask(f"{healthy}:motor.vel=(20)") == ""
    h.advance(0.05)
    assert h.world.motors[f"{healthy}.motor"] == 0.2
    assert value(c.ask(f"{healthy}:{healthy}.get=()"), f"{healthy}:motor.vel") == "20"
    refused = c.ask(f"{bad}:motor.vel=(10)")
    assert refused.startswith(f"{bad}:motor.error=(fault,module {bad} is fault: ") or \
        refused.startswith(f"{bad}:motor.error=(not_attached,module {bad} is detached: "), \
        refused
    assert h.world.motors.get(f"{bad}.motor", 0.0) == 0.0
    assert c.ask("") == ""


# -- a module plugin --------------------------------------------------------------------------
#: How each runtime bug is met: a request (or only time passing).
MODULE_TRIGGERS: dict[str, Callable[[Harness, Client], None]] = {
    "is_moving": lambda h, c: _asks(c, "arm:motor.vel=(40)"),  # asks every module
    "stop": lambda h, c: _asks(c, "robot:robot.stop=()"),
    "vel": lambda h, c: _asks(c, "crane:motor.vel=(60)", "fault"),
    "pulse": lambda h, c: _asks(c, "crane:motor.pulse=(60)", "fault"),
    "lamp": lambda h, c: _asks(c, "crane:lamp.on=(1)", "fault"),
    "task": lambda h, c: None,  # its 10 Hz task raises on the next tick
}


def _asks(c: Client, request: str, error: str = "") -> None:
    """`request`, whose answer is `error` the first time (later, while the module is
    faulted, it is refused as any request to it)."""
    answer = c.ask(request)
    target = request.split("=")[0].rsplit(".", 1)[0]
    if "is fault: " in answer:
        return
    if error:
        assert answer.startswith(f"{target}.error=({error},internal error PluginBug"), answer
    else:
        assert answer == "", answer


@pytest.mark.parametrize("method", sorted(MODULE_TRIGGERS))
def test_a_module_method_raising_faults_that_module_with_its_motor_zeroed(
        method: str, caplog: pytest.LogCaptureFixture) -> None:
    h = harness(MODULE_YAML)
    try:
        c = h.connect()
        assert c.ask("crane:motor.vel=(50)arm:motor.vel=(30)") == ""
        h.advance(0.05)
        assert h.world.motors["crane.motor"] == 0.5
        FaultyModule.broken = {method}
        with caplog.at_level(logging.DEBUG, logger="ramp"):
            for attempt in range(3):  # the bug again after each re-attach
                if attempt:
                    FaultyModule.broken = set()  # fixed for a moment: re-attached
                    keep_talking(h, c, 2.2)
                    assert h.sup.slots["crane"].state == "ok"
                    FaultyModule.broken = {method}
                MODULE_TRIGGERS[method](h, c)
                h.advance(0.1)
                assert h.sup.slots["crane"].state == "fault"
                assert h.world.motors["crane.motor"] == 0.0  # zeroed by the bus layer
                assert "PluginBug" in h.sup.slots["crane"].reason
                get = c.ask("robot:robot.get=()")
                assert value(get, "robot:crane.state") == "fault"
                assert value(get, "robot:arm.state") == "ok"
        if method not in ("stop", "is_moving"):
            assert h.world.motors["arm.motor"] == 0.3  # nobody stopped it
        others_serve(h, c, "crane")
        assert len(tracebacks(caplog)) == 1, tracebacks(caplog)
    finally:
        h.close()


@pytest.mark.parametrize("method", ["start", "tasks"])
def test_a_module_whose_start_or_tasks_raises_never_moves_and_the_rest_serve(
        method: str, caplog: pytest.LogCaptureFixture) -> None:
    """`start` (at every attach) and `tasks` (once, at start-up) raising: the module is in
    `fault` from the start, and `ramp run`'s other modules start and serve."""
    FaultyModule.broken = {method}
    with caplog.at_level(logging.DEBUG, logger="ramp"):
        h = harness(MODULE_YAML)
        try:
            c = h.connect()
            get = keep_talking(h, c, 3.0)  # `start` is tried again about once a second
            assert value(get, "robot:crane.state") == "fault"
            assert value(get, "robot:arm.state") == "ok"
            assert f"{method} raised PluginBug" in h.sup.slots["crane"].reason
            assert h.world.motors.get("crane.motor", 0.0) == 0.0
            others_serve(h, c, "crane")
        finally:
            h.close()
    assert len(tracebacks(caplog)) == 1, tracebacks(caplog)


def test_a_property_that_raises_costs_only_its_row(caplog: pytest.LogCaptureFixture) -> None:
    h = harness(MODULE_YAML)
    try:
        c = h.connect()
        assert c.ask("crane:motor.vel=(50)") == ""
        FaultyModule.broken = {"get"}
        with caplog.at_level(logging.DEBUG, logger="ramp"):
            for _ in range(5):
                h.advance(0.1)
                get = c.ask("crane:crane.get=()")
                assert get.startswith("crane:motor.vel=(50)crane:lamp.on=(0)"), get
                assert "crane:motor.error=(fault,reading motor.temp raised PluginBug)" in get
        assert h.sup.slots["crane"].state == "ok"  # the module itself keeps working
        assert h.world.motors["crane.motor"] == 0.5
        assert len(tracebacks(caplog)) == 1
        FaultyModule.broken = set()
        h.advance(0.1)
        assert "crane:motor.temp=(21)" in c.ask("crane:crane.get=()")
    finally:
        h.close()


def test_a_read_function_that_raises_costs_only_its_answer(
        caplog: pytest.LogCaptureFixture) -> None:
    h = harness(MODULE_YAML)
    try:
        c = h.connect()
        assert c.ask("crane:motor.load=()") == "crane:motor.load=(0)"
        assert c.ask("crane:motor.vel=(50)") == ""
        FaultyModule.broken = {"read"}
        with caplog.at_level(logging.DEBUG, logger="ramp"):
            for _ in range(5):
                h.advance(0.1)
                answer = c.ask("crane:motor.load=()arm:arm.get=()")
                assert answer.startswith("crane:motor.error=(fault,internal error PluginBug)"
                                         "arm:motor.vel=(0)"), answer
        assert h.sup.slots["crane"].state == "ok"  # reading moves nothing: it keeps working
        assert h.world.motors["crane.motor"] == 0.5
        assert len(tracebacks(caplog)) == 1
    finally:
        h.close()


# -- a driver plugin --------------------------------------------------------------------------
def _reopen(h: Harness, c: Client) -> None:
    """The device vanishes for a moment: the bus is closed and opened again."""
    h.world.unplugged.add("bad")
    h.advance(0.05)
    h.world.unplugged.discard("bad")


def _stall(h: Harness, c: Client) -> None:
    """The loop does not run for 0.6 s: the stall handler's zeros on every wire."""
    h.clock.advance(0.6)


DRIVER_TRIGGERS: dict[str, Callable[[Harness, Client], None]] = {
    "open": _reopen,
    "fileno": _reopen,
    "ready": lambda h, c: None,  # asked again within a second
    "waiting": lambda h, c: None,
    "tick": lambda h, c: None,  # its read path, every tick
    "input": lambda h, c: _poke(h),
    "command": lambda h, c: _asks(c, "winch:motor.vel=(60)"),  # the write path
    "output": lambda h, c: _toggle(c),
    "stop_motors": _stall,
    "close": lambda h, c: h.world.unplugged.add("bad"),  # a fault closes it
}
#: How long each bug takes to fault its bus: a reopen waits for the next retry (about a
#: second), readiness is asked again at it; the others act at once.
DRIVER_WAIT = {"open": 2.5, "fileno": 2.5, "ready": 1.2, "waiting": 1.2}


def _toggle(c: Client) -> None:
    """The lamp switched (whatever it was before: a write of its state sends nothing)."""
    for on in (0, 1):
        _asks(c, f"winch:lamp.on=({on})")


def _poke(h: Harness) -> None:
    assert FaultyBus.last is not None
    FaultyBus.last.poke()
    h.pump_io()


@pytest.mark.parametrize("method", sorted(DRIVER_TRIGGERS))
def test_a_driver_method_raising_faults_its_bus_and_zeroes_its_motors(
        method: str, caplog: pytest.LogCaptureFixture) -> None:
    h = harness(DRIVER_YAML)
    try:
        c = h.connect()
        assert c.ask("winch:motor.vel=(50)arm:motor.vel=(30)") == ""
        h.advance(0.05)
        assert h.world.motors["winch.motor"] == 0.5
        FaultyBus.broken = {method}
        with caplog.at_level(logging.DEBUG, logger="ramp"):
            for attempt in range(3):  # the bug again after each retry of the bus
                if attempt:
                    FaultyBus.broken = set()  # fixed for a moment: the retry brings it back
                    h.world.unplugged.discard("bad")
                    keep_talking(h, c, 2.5)
                    assert h.sup.slots["winch"].state == "ok"
                    assert c.ask("winch:motor.vel=(50)") == ""
                    h.advance(0.05)
                    assert h.world.motors["winch.motor"] == 0.5
                    FaultyBus.broken = {method}
                DRIVER_TRIGGERS[method](h, c)
                get = keep_talking(h, c, DRIVER_WAIT.get(method, 0.2))
                assert value(get, "robot:winch.state") == "fault"
                assert value(get, "robot:arm.state") == "ok"
                assert h.world.motors["winch.motor"] == 0.0  # zeros written, or port closed
                reason = h.sup.slots["winch"].reason
                assert reason.startswith("bus bad: "), reason
                if method != "close":  # a close bug is met after the fault that closes it
                    assert "PluginBug" in reason, reason
        others_serve(h, c, "winch")
        assert len(tracebacks(caplog)) == 1, tracebacks(caplog)
        assert h.sup.bus_manager.health["bad"].faults >= 3
    finally:
        h.close()  # a driver that raises on close too: the others still close
    assert not any(b.is_open for b in h.sup.buses.values())


def test_a_driver_bug_logs_its_traceback_once_per_fault_episode(
        caplog: pytest.LogCaptureFixture) -> None:
    """A message that varies (a counter) is the same bug within an episode; once the bus
    has run clean for QUIET_S, the next bug is a new episode with its own traceback."""
    from ramp.runtime.buses import QUIET_S

    h = harness(DRIVER_YAML)
    try:
        c = h.connect()
        with caplog.at_level(logging.DEBUG, logger="ramp"):
            FaultyBus.broken = {"tick"}
            keep_talking(h, c, 3.0)
            assert len(tracebacks(caplog)) == 1
            FaultyBus.broken = set()
            keep_talking(h, c, QUIET_S + 2.0)
            assert value(c.ask("robot:robot.get=()"), "robot:winch.state") == "ok"
            FaultyBus.broken = {"tick"}
            keep_talking(h, c, 3.0)
        assert len(tracebacks(caplog)) == 2
        assert all(isinstance(r.exc_info[1], Exception) for r in caplog.records
                   if r.exc_info is not None)
    finally:
        h.close()


def test_the_faulty_plugins_are_a_distribution_s_entry_points() -> None:
    from ramp.registry import drivers, modules

    assert modules().entry("crane").distribution == DIST
    assert drivers().entry("faultybus").distribution == DIST


# -- at start-up ------------------------------------------------------------------------------
PLUGIN = "acme-faulty's entry point crane = tests.hil_sim.faulty_plugins:FaultyModule"
DRIVER = "acme-faulty's entry point faultybus = tests.hil_sim.faulty_plugins:FaultyBus"


@pytest.mark.parametrize(("yaml_text", "broken", "module", "state", "reason"), [
    (MODULE_YAML, "init", "crane", "fault", f"{PLUGIN} raised when built: "),
    (MODULE_YAML, "start", "crane", "fault", "start raised PluginBug: start is broken "),
    (DRIVER_YAML, "init", "winch", "fault", f"bus bad: {DRIVER} raised when built: "),
    (DRIVER_YAML, "open", "winch", "detached", "bus bad: open failed: PluginBug: "),
], ids=["module-init", "module-start", "driver-init", "driver-open"])
def test_a_plugin_that_fails_at_start_up_is_named_and_the_rest_start(
        yaml_text: str, broken: str, module: str, state: str, reason: str,
        caplog: pytest.LogCaptureFixture) -> None:
    """SPEC 2.2: the rest of the robot starts and serves; the broken plugin is reported by
    its distribution and entry point, in the log and in its module's reason."""
    (FaultyModule if yaml_text is MODULE_YAML else FaultyBus).broken = {broken}
    with caplog.at_level(logging.DEBUG, logger="ramp"):
        h = harness(yaml_text)
        try:
            c = h.connect()
            get = keep_talking(h, c, 2.5)
            assert value(get, f"robot:{module}.state") == state
            assert value(get, "robot:arm.state") == "ok"
            why = h.sup.slots[module].reason
            assert reason in why, why
            assert "acme-faulty's entry point" in why, why
            others_serve(h, c, module)
        finally:
            h.close()
    assert "acme-faulty's entry point" in caplog.text
    assert len(tracebacks(caplog)) == 1, tracebacks(caplog)


def test_ramp_run_starts_without_a_module_type_that_fails_to_import(tmp_path: Any) -> None:
    """An installed distribution (`acme-broken`) whose module type raises at import: `ramp
    check` refuses the file naming the distribution and entry point at the YAML key; `ramp
    run` logs the same, starts the rest of the robot, and answers for the broken module
    with `fault` and that reason."""
    import socket
    import subprocess
    import sys

    from tests.harness import REPO, ask_line, start_ramp, stop_process

    (tmp_path / "acme_broken").mkdir()
    (tmp_path / "acme_broken" / "__init__.py").write_text("LIMIT = 1 / 0\n")
    info = tmp_path / "acme_broken-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: acme-broken\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[ramp.modules]\ncrane = acme_broken:Crane\n")
    config = tmp_path / "robot.yaml"
    config.write_text("server: {host: 127.0.0.1, port: 0}\n"
                      "buses:\n  io: {driver: sim}\n"
                      "modules:\n"
                      "  crane: {type: crane, motor: {bus: io}}\n"
                      "  demo: {motor: {bus: io}, lamp: {bus: io}}\n")
    env = {"PYTHONPATH": str(tmp_path)}
    check = subprocess.run([sys.executable, "-m", "ramp.cli", "check", str(config)], cwd=REPO,
                           capture_output=True, text=True, timeout=60,
                           env={**__import__("os").environ, **env})
    assert check.returncode == 2
    assert f"{config}:5: modules.crane.type: module type 'crane' (entry point crane = " \
           "acme_broken:Crane in ramp.modules of acme-broken) cannot be loaded: " in check.stderr
    assert f"{tmp_path / 'acme_broken' / '__init__.py'}:1: ZeroDivisionError" in check.stderr
    proc, host, port = start_ramp(["--sim", "--config", str(config)], env=env)
    try:
        with socket.create_connection((host, port), timeout=5) as s:
            assert ask_line(s, "robot:robot.modules=()") == "robot:robot.modules=(demo)"
            assert "robot:crane.state=(fault)" in ask_line(s, "robot:robot.get=()")
            refused = ask_line(s, "crane:motor.vel=(10)")
            assert refused.startswith("crane:motor.error=(fault,module crane is fault: module "
                                      "type 'crane' "), refused
            assert "of acme-broken" in refused
            assert ask_line(s, "demo:motor.vel=(30)") == ""
            assert "demo:motor.vel=(30)" in ask_line(s, "demo:demo.get=()")
    finally:
        stop_process(proc)
        _, err = proc.communicate()
    assert "cannot be loaded" in err and "acme-broken" in err
    assert "the rest of the robot starts without it" in err
