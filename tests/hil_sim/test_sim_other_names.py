"""`ramp run --sim` with module names other than MARTE's: the signals the physics model
knows drive it, the rest are simulated plainly. It used to raise KeyError at start-up."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from tests.harness import MARTE_YAML, SimHarness, end_process
from tests.harness import ask_line as ask
from tests.harness import start_ramp as start

#: MARTE with the BLE renamed `digger`: none of its signals are the model's any more (its
#: interlocks follow the new name).
RENAMED = MARTE_YAML.replace("\n  ble:\n", "\n  digger:\n    type: ble\n").replace(
    "ble:", "digger:")


def test_renamed_modules_attach_and_answer_while_known_ones_still_move_the_model() -> None:
    assert RENAMED != MARTE_YAML
    h = SimHarness(RENAMED)
    try:
        c = h.connect()
        assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(base,digger)"
        assert "digger:lift.pos=(" in c.ask("digger:digger.get=()")
        assert c.ask("digger:chain.vel=(40)") == ""
        h.advance(0.05)
        chain = h.backplane.sabertooth["ble_motors"].emulator
        assert chain.duty(130, 1) > 0.3  # on the wire, through the real driver
        assert h.backplane.signals.plain.motors["digger.chain_left"] > 0.3
        h.world.place(2.0, 1.94, 0.0)
        # The chain stops first: with the ladder down and the chain running, MARTE's
        # digging_creep interlock holds the drive to a creep (until 0.1 s after it stops).
        assert c.ask("digger:chain.vel=(0)") == ""
        h.advance(0.2)
        assert c.ask("base:base.drive=(100,0)") == ""
        for _ in range(10):
            h.advance(0.1)
            assert c.ask("") == ""
        assert h.world.x > 2.1  # the base's signals are the model's: MARTE moved
    finally:
        h.close()


@pytest.mark.timeout(60)
def test_ramp_run_sim_starts_with_module_names_of_its_own(tmp_path: Path) -> None:
    cfg = tmp_path / "robot.yaml"
    cfg.write_text(RENAMED.replace("\n  base:\n", "\n  chassis:\n    type: base\n").replace(
        "base:base.", "chassis:chassis.").replace("base:", "chassis:"))
    proc, host, port = start(["--sim", "--config", str(cfg), "--host", "127.0.0.1",
                              "--port", "0"])
    try:
        with socket.create_connection((host, port), timeout=10) as s:
            assert ask(s, "robot:robot.modules=()") == "robot:robot.modules=(chassis,digger)"
            assert ask(s, "chassis:chassis.drive=(30,0)") == ""
            assert "chassis:lf_wheel.vel=(30)" in ask(s, "chassis:chassis.get=()")
    finally:
        _, err = end_process(proc)
    assert proc.returncode == 0, err
    assert "KeyError" not in err and "Traceback" not in err
