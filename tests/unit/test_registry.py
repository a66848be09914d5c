"""The plugin registries (SPEC 10): one lazy table per entry point group, RAMP's own entries
declared like a plugin's, and a name registered twice an error naming both packages."""

from __future__ import annotations

import sys

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


@pytest.fixture
def acme(tmp_path, monkeypatch: pytest.MonkeyPatch):  # type: ignore[no-untyped-def]
    """A plugin distribution `acme-crane` with broken entries beside RAMP's own."""
    import ramp.registry as registry_module
    from ramp.registry import _installed

    pkg = tmp_path / "acme_crane"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "broken.py").write_text("import math\nSPEED = 1 / 0\n")
    (pkg / "typo.py").write_text("def f(:\n    pass\n")
    (pkg / "notamodule.py").write_text("class Crane:\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    fake = [Entry("crane", "acme_crane.broken:Crane", "acme-crane"),
            Entry("typo", "acme_crane.typo:Crane", "acme-crane"),
            Entry("plain", "acme_crane.notamodule:Crane", "acme-crane")]
    monkeypatch.setitem(registry_module._REGISTRIES, "ramp.modules",
                        Registry("ramp.modules", _installed("ramp.modules") + fake))
    monkeypatch.setitem(registry_module._REGISTRIES, "ramp.drivers",
                        Registry("ramp.drivers", _installed("ramp.drivers") + [
                            Entry("winchbus", "acme_crane.broken:Bus", "acme-crane"),
                            Entry("plainbus", "acme_crane.notamodule:Crane", "acme-crane")]))
    yield pkg
    for name in ("acme_crane", "acme_crane.broken", "acme_crane.typo", "acme_crane.notamodule"):
        sys.modules.pop(name, None)


def test_a_module_type_that_fails_to_import_is_a_config_error_naming_the_plugin(acme) -> None:  # type: ignore[no-untyped-def]
    """Not a traceback out of `ramp check`: the YAML's file:line:key, the entry point, its
    distribution, and the plugin's own file:line."""
    _, errors = parse_config("modules:\n  m:\n    type: crane\n  t:\n    type: typo\n",
                             "r.yaml")
    first, second = (str(e) for e in errors)
    assert first.startswith("r.yaml:3: modules.m.type: module type 'crane' (entry point "
                            "crane = acme_crane.broken:Crane in ramp.modules of acme-crane) "
                            "cannot be loaded: ")
    assert f"{acme / 'broken.py'}:2: ZeroDivisionError" in first
    assert second.startswith("r.yaml:5: modules.t.type: module type 'typo'")
    assert f"{acme / 'typo.py'}:1: SyntaxError" in second


def test_a_module_type_that_is_not_a_module_is_refused_at_registration(acme) -> None:  # type: ignore[no-untyped-def]
    _, errors = parse_config("modules:\n  m:\n    type: plain\n", "r.yaml")
    assert len(errors) == 1
    text = str(errors[0])
    assert text.startswith("r.yaml:3: modules.m.type: module type 'plain' (entry point plain = "
                           "acme_crane.notamodule:Crane in ramp.modules of acme-crane) is ")
    assert text.endswith("not a ramp.api.Module subclass")


def test_a_driver_that_fails_to_load_is_a_config_error_naming_the_plugin(acme) -> None:  # type: ignore[no-untyped-def]
    _, errors = parse_config("buses:\n  w:\n    driver: winchbus\n  p:\n    driver: plainbus\n",
                             "r.yaml")
    first, second = (str(e) for e in errors)
    assert first.startswith("r.yaml:3: buses.w.driver: driver 'winchbus' (entry point "
                            "winchbus = acme_crane.broken:Bus in ramp.drivers of acme-crane) "
                            "cannot be loaded: ")
    assert f"{acme / 'broken.py'}:2: ZeroDivisionError" in first
    assert second.startswith("r.yaml:5: buses.p.driver: driver 'plainbus'")
    assert second.endswith("not a ramp.api.Bus subclass")
