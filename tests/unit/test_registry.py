"""The plugin registries (SPEC 10): one lazy table per entry point group, RAMP's own entries
declared like a plugin's, and a name registered twice an error naming both packages."""

from __future__ import annotations

import pytest

from ramp.config import parse_config
from ramp.registry import Entry, Registry, RegistryError, drivers, emulators, modules


def test_ramp_registers_its_own_modules_drivers_and_emulators_through_entry_points() -> None:
    for reg, names in ((modules(), {"base", "ble", "diff_base", "demo"}),
                       (drivers(), {"sim", "sabertooth", "phidget", "can"}),
                       (emulators(), {"bus.sabertooth", "bus.can", "module.base",
                                      "module.ble", "module.diff_base"})):
        for name in names:
            assert reg.entry(name).distribution == "ramp", (reg.group, name)


def test_the_arm_plugin_is_found_through_its_own_package() -> None:
    assert modules().entry("arm").distribution == "ramp-arm"
    assert emulators().entry("module.arm").distribution == "ramp-arm"
    assert modules().load("arm").__module__ == "ramp_arm.module"


def test_a_name_registered_by_two_packages_is_an_error_naming_both() -> None:
    reg = Registry("ramp.drivers", [
        Entry("can", "ramp.hal.odrive:ODriveBus", "ramp"),
        Entry("can", "acme_can.bus:AcmeBus", "acme-can"),
        Entry("sim", "ramp.hal.simio:SimBus", "ramp"),
    ])
    with pytest.raises(RegistryError) as err:
        reg.load("can")
    assert "ramp (ramp.hal.odrive:ODriveBus)" in str(err.value)
    assert "acme-can (acme_can.bus:AcmeBus)" in str(err.value)
    assert reg.load("sim").__name__ == "SimBus"  # the other names keep working


def test_one_package_seen_twice_on_the_path_is_one_registration() -> None:
    e = Entry("sim", "ramp.hal.simio:SimBus", "ramp")
    assert Registry("ramp.drivers", [e, e]).load("sim").__name__ == "SimBus"


def test_entries_are_imported_only_when_used() -> None:
    reg = Registry("ramp.drivers", [Entry("ghost", "no_such_package.bus:Bus", "ghost"),
                                    Entry("sim", "ramp.hal.simio:SimBus", "ramp")])
    assert reg.names() == ["ghost", "sim"]
    assert reg.load("sim").__name__ == "SimBus"
    with pytest.raises(ImportError):
        reg.load("ghost")


def test_an_entry_pointing_at_nothing_says_so() -> None:
    reg = Registry("ramp.modules", [Entry("x", "ramp.modules.demo:Nope", "acme")])
    with pytest.raises(RegistryError, match="acme.*ramp.modules.demo:Nope"):
        reg.load("x")


def test_an_unknown_module_type_is_a_config_error_listing_the_valid_ones() -> None:
    _, errors = parse_config("modules:\n  m:\n    type: crane\n", "r.yaml")
    text = str(errors[0])
    assert text.startswith("r.yaml:3: modules.m.type: unknown module type 'crane' (expected "
                           "one of:")
    for name in ("arm", "base", "ble", "demo", "diff_base"):
        assert name in text


def test_a_module_without_type_is_its_own_type() -> None:
    _, errors = parse_config("modules:\n  crane: {}\n", "r.yaml")
    assert "modules.crane.type: unknown module type 'crane'" in str(errors[0])
