"""The battery's charge from its per-robot model (issue 35 item 3): volts -> % by the pack's
cells and chemistry or its own curve, checked in YAML like every other key."""

from __future__ import annotations

from pathlib import Path

import pytest

from ramp.config.loader import check_config
from ramp.layers.functional.battery import Charge, ChargeModel
from tests.harness import REPO


def test_a_3s_lipo_reads_full_at_12_6_v_and_empty_at_9_8_v() -> None:
    model = ChargeModel.of_cells(3, "lipo")
    assert model.charge(12.6) == 100.0
    assert 95.0 <= model.charge(12.57) <= 100.0  # Scout's fresh pack, once shown as 0 %
    assert model.charge(9.8) == 0.0
    assert 40.0 < model.charge(11.5) < 60.0


def test_a_curve_is_interpolated_and_clamped() -> None:
    model = ChargeModel.from_params({"curve": [[10.0, 0.0], [12.0, 100.0]]})
    assert model is not None
    assert model.charge(11.0) == 50.0
    assert model.charge(13.0) == 100.0 and model.charge(9.0) == 0.0
    assert model.charge(float("nan")) == 0.0


def test_with_no_model_the_cell_count_is_guessed_from_the_first_reading() -> None:
    for volts, pct in ((12.57, 95.0), (21.0, 100.0), (8.4, 100.0)):
        charge = Charge(lambda v=volts: v, {})
        assert charge.read() >= pct, volts
        assert charge.model is not None and charge.model.guessed


def _yaml_with(tmp_path: Path, battery: str) -> Path:
    text = (REPO / "ramp.yaml").read_text()
    line = next(x for x in text.splitlines() if x.strip().startswith("battery:"))
    out = tmp_path / "ramp.yaml"
    out.write_text(text.replace(line, f"    battery: {battery}"))
    return out


@pytest.mark.parametrize(("battery", "key", "words"), [
    ("{bus: sbc_io, channel: 0, cells: 5, chemistry: lipon}", "battery.chemistry",
     "one of lipo"),
    ("{bus: sbc_io, channel: 0, cells: 49}", "battery.cells", "number of cells"),
    ("{bus: sbc_io, channel: 0, curve: [[20, 50], [19, 60]]}", "battery.curve",
     "volts rising"),
    ("{bus: sbc_io, channel: 0, curve: [[17, 0], [21, 120]]}", "battery.curve",
     "percent 0-100"),
    ("{bus: sbc_io, channel: 0, curve: [[17, 0], [21, 100]], cells: 5}", "battery.curve",
     "not both"),
])
def test_ramp_check_names_file_line_and_key_of_a_bad_model(tmp_path: Path, battery: str,
                                                             key: str, words: str) -> None:
    path = _yaml_with(tmp_path, battery)
    _, errors = check_config(path)
    text = "\n".join(str(e) for e in errors)
    assert errors, battery
    assert f"modules.base.{key}" in text and words in text, text
    line = 1 + next(i for i, x in enumerate(path.read_text().splitlines())
                    if x.strip().startswith("battery:"))
    assert f"{path}:{line}:" in text, text


def test_marte_and_scout_ship_their_models() -> None:
    for name in ("ramp.yaml", "examples/robots/scout.yaml"):
        config, errors = check_config(REPO / name)
        assert not errors and config is not None
        battery = config.modules["base"].devices["battery"].params
        assert battery.get("cells") and battery.get("chemistry") == "lipo", name


def test_a_battery_with_no_model_still_checks_and_builds(tmp_path: Path) -> None:
    """The loader fills the model's defaults in (`cells: 0`, not given) and the module checks
    them again when built (tests/hil_sim/test_driver_bugs.py builds one with no model)."""
    path = _yaml_with(tmp_path, "{bus: sbc_io, channel: 0}")
    config, errors = check_config(path)
    assert not errors and config is not None
    params = config.modules["base"].devices["battery"].params
    assert 70.0 < Charge(lambda: 20.0, params).read() < 85.0  # 5 cells guessed: 4.0 V each
