"""`ramp.yaml` -> validated, frozen configuration.

Every error names the file, the line, the key path and what was expected, and all of them
are collected in one pass so `ramp check` can show a team everything to fix at once.
Drivers and modules declare their own keys and the rules spanning them (`Bus.fields`,
`Bus.channel_fields`, `Module.devices`, `Module.settings`); this loader only walks the tree
and runs the one block check (`ramp.schema.validate`) on each. It produces data and builds
nothing: drivers and modules are built from that data by `ramp.runtime.build`, so `ramp
check` touches no hardware and runs no module code.

Hostile or broken files end in such an error too, never in a traceback or a hang: the file
is read by `ramp.common.yamlload` (a regular file of at most `MAX_FILE_BYTES` of UTF-8,
nesting capped, alias expansion capped, so a kilobyte "billion laughs" that once took 14 s
and 800 MB fails at once), keys must be names (a list or mapping as a key is reported where
it is), values are cut short in messages, and YAML merge keys (`<<: *defaults`) work as YAML
says: explicit keys override merged ones.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ramp.common.hostport import valid_host
from ramp.common.yamlload import (
    MAX_FILE_BYTES,
    BadKey,
    LinedMap,
    YamlError,
    kind_of,
    parse_mapping,
    read_text,
)
from ramp.config.access import AccessConfig, TlsConfig, check_access, check_exposure, check_tls
from ramp.config.interlocks import check_interlocks
from ramp.errors import ConfigError, ConfigErrors, PluginError
from ramp.fleetconf import problems as fleet_problems
from ramp.hal import driver_class
from ramp.hal.interfaces import Bus
from ramp.layers.module_distribution import Module
from ramp.layers.robot_distribution.interlocks import RuleSpec
from ramp.layers.robot_distribution.watchdog import MAX_TIMEOUT_S, MIN_TIMEOUT_S
from ramp.modules import module_class
from ramp.recorder.config import RECORDER_FIELDS, RecorderConfig
from ramp.registry import PluginLoadError
from ramp.schema import Block, Field, shorten, validate

#: A module's name is an MCP name (`base:base.get=()`), and `robot` is taken.
MODULE_NAME = re.compile(r"[A-Za-z0-9_]{1,32}")


SERVER_FIELDS = {
    "host": Field(str, "127.0.0.1", what="a host name or address (loopback unless TLS)"),
    "port": Field(int, 5577, lo=0, hi=65535, what="a TCP port"),
    "max_clients": Field(int, 8, lo=1, hi=4096, what="a number of clients"),
    "max_line": Field(int, 4096, lo=64, hi=1 << 20, what="a message length in bytes"),
    "max_output": Field(int, 1 << 20, lo=4096, hi=1 << 28,
                        what="bytes of unsent responses before a client is cut off"),
}
WATCHDOG_FIELDS = {
    "timeout": Field(float, 1.0, lo=MIN_TIMEOUT_S, hi=MAX_TIMEOUT_S, what="a timeout in seconds"),
}
SCHEDULER_FIELDS = {
    "rate_hz": Field(float, 100.0, lo=1.0, hi=1000.0, what="a tick rate in Hz"),
    "stall_limit": Field(float, 0.25, lo=0.02, hi=10.0,
                         what="seconds a tick may stall before motors are stopped"),
    "idle_rate_hz": Field(float, None, lo=1.0, hi=1000.0,
                          what="a tick rate in Hz while nothing moves (the base rate: never "
                               "slower)"),
}
BUS_COMMON = {"driver", "sim"}


@dataclass(frozen=True)
class ServerConfig:
    host: str = "127.0.0.1"
    port: int = 5577
    max_clients: int = 8
    max_line: int = 4096
    max_output: int = 1 << 20
    #: `server.tls` (SPEC 13): mutual TLS on the MCP port; None serves plain TCP.
    tls: TlsConfig | None = None


@dataclass(frozen=True)
class BusConfig:
    name: str
    driver: str
    params: Mapping[str, Any]
    sim: bool = True  # replaced by its emulator under --sim
    line: int = 0
    #: Why its driver's code cannot be loaded (a `PluginError`); "" when it can.
    broken: str = ""


@dataclass(frozen=True)
class DeviceConfig:
    name: str
    bus: str
    kind: str
    channel: Mapping[str, Any]
    params: Mapping[str, Any]
    line: int = 0


@dataclass(frozen=True)
class ModuleConfig:
    name: str
    type: str
    devices: Mapping[str, DeviceConfig]
    settings: Mapping[str, Mapping[str, Any]]
    line: int = 0
    #: Why its type's code cannot be loaded, or its bus's driver's (a `PluginError`); ""
    #: when it can. `ramp run` starts the rest, this module in `fault` for good.
    broken: str = ""


@dataclass(frozen=True)
class Config:
    file: str
    server: ServerConfig = ServerConfig()
    watchdog_timeout: float = 1.0
    rate_hz: float = 100.0
    stall_limit: float = 0.25
    #: `scheduler.idle_rate_hz`: the tick rate while nothing moves; None (not set): 20 Hz on
    #: the wall clock, every tick on a virtual one (`ramp.runtime.build.IDLE_RATE_HZ`).
    idle_rate_hz: float | None = None
    buses: Mapping[str, BusConfig] = field(default_factory=dict)
    modules: Mapping[str, ModuleConfig] = field(default_factory=dict)
    #: The flight recorder (`recorder:`), None when the block is absent: not recording.
    recorder: RecorderConfig | None = None
    #: Line of some keys (`server.max_clients`), for checks made at run time.
    lines: Mapping[str, int] = field(default_factory=dict)
    #: The checked rules of `interlocks:` (SPEC 11), in file order.
    interlocks: tuple[RuleSpec, ...] = ()
    #: `access:` (SPEC 13): roles, identities, revocations and per-client caps.
    access: AccessConfig = AccessConfig()


class _Checker:
    """Walks the YAML tree collecting errors instead of stopping at the first."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.errors: list[ConfigError] = []

    def err(self, key: str, line: int, message: str) -> None:
        self.errors.append(ConfigError(shorten(message, 300), file=self.file, line=line,
                                       key=shorten(key, 120)))

    def plugin(self, key: str, line: int, message: str) -> None:
        """A plugin whose code raised at import (see `PluginError`)."""
        self.errors.append(PluginError(shorten(message, 600), file=self.file, line=line,
                                       key=shorten(key, 120)))

    def block(self, parent: LinedMap, key: str, path: str, fields: Mapping[str, Field],
              skip: set[str] | frozenset[str] = frozenset()) -> dict[str, Any]:
        """Check the mapping `parent[key]` against `fields`; returns values (defaults on error)."""
        raw = parent.get(key)
        line = parent.lines.get(key, parent.line)
        if raw is None:
            raw = LinedMap()
            raw.line = line
        if not isinstance(raw, dict):
            self.err(path, line, f"expected a mapping, got {kind_of(raw)}")
            return {k: f.default for k, f in fields.items() if not f.required}
        return self.values(raw, path, fields, skip)

    def values(self, raw: dict[Any, Any], path: str, fields: Mapping[str, Field],
               skip: set[str] | frozenset[str] = frozenset()) -> dict[str, Any]:
        """`ramp.schema.validate` on one block, each problem at its key's line (a rule
        spanning the block at the block's own line)."""
        here = getattr(raw, "line", 0)
        lines = {str(k): v for k, v in getattr(raw, "lines", {}).items()}
        for dup, dline in getattr(raw, "duplicates", []):
            self.err(f"{path}.{dup}", dline, "key given twice")
        out, problems = validate(fields, raw, skip)
        for key, message in problems:
            self.err(f"{path}.{key}" if key else path, lines.get(key, here), message)
        return out




def load_config(path: str | Path) -> Config:
    """Load and check a config file; raises ConfigErrors listing every problem."""
    config, errors = check_config(path)
    if errors or config is None:
        raise ConfigErrors(errors)
    return config


def check_config(path: str | Path) -> tuple[Config | None, list[ConfigError]]:
    """(config or None, every error found) without touching any hardware.

    A robot's file must exist, be UTF-8, hold at most MAX_FILE_BYTES and name at least one
    module; `parse_config` (text, used by tests and tools) does not insist on modules."""
    name = str(path)
    try:
        text = read_text(path, max_bytes=MAX_FILE_BYTES, what="a config file")
    except YamlError as exc:
        return None, [ConfigError(exc.problem, file=name, line=exc.line)]
    config, errors = parse_config(text, name)
    if errors or config is None:
        return config, errors
    if not config.modules:
        what = "the file is empty" if not text.strip(" \t\r\n#") or not _has_content(text) \
            else "no modules"
        return None, [ConfigError(f"{what}; expected a modules section naming at least one "
                                  "module (see ramp.yaml)", file=name, line=1, key="modules")]
    return config, errors


def _has_content(text: str) -> bool:
    return any(line.strip() and not line.lstrip().startswith("#") for line in text.splitlines())


def parse_config(text: str, name: str = "ramp.yaml") -> tuple[Config | None, list[ConfigError]]:
    try:
        root = parse_mapping(text, "a mapping of sections")
    except YamlError as exc:
        return None, [ConfigError(exc.problem, file=name, line=exc.line)]
    # SPEC 14: `fleet:` is checked here and used by ramp-fleet-agent (ramp/fleetconf.py).
    fleet = root.pop("fleet", None) if isinstance(root, dict) else None

    c = _Checker(name)
    _report_bad_keys(c, root)
    top = {"server", "watchdog", "scheduler", "buses", "modules", "recorder", "interlocks",
           "access"}
    for k in root:
        if k not in top:
            c.err(str(k), root.lines.get(k, 1),
                  f"unknown section (expected one of: {', '.join(sorted(top))})")
    for dup, dline in root.duplicates:
        c.err(str(dup), dline, "section given twice")
    server = c.block(root, "server", "server", SERVER_FIELDS, skip={"tls"})
    _check_host(c, root, server)
    tls, access = _access(c, root, name, server)
    wd = c.block(root, "watchdog", "watchdog", WATCHDOG_FIELDS)
    sched = c.block(root, "scheduler", "scheduler", SCHEDULER_FIELDS)
    _check_watchdog_tick(c, root, wd["timeout"], sched["rate_hz"])
    recorder = _recorder(c, root, name)
    if fleet is not None:
        for key, line, message in fleet_problems(fleet):
            c.err(key, line, message)
    buses, bus_classes = _buses(c, root)
    def mistakes() -> int:  # a plugin that cannot load leaves its module's name checkable
        return sum(not isinstance(e, PluginError) for e in c.errors)

    modules_errors = mistakes()
    modules = _modules(c, root, buses, bus_classes)
    interlocks = check_interlocks(root.get("interlocks"), root.lines.get("interlocks", 1),
                                  modules, c.err, modules_ok=mistakes() == modules_errors)
    if any(not isinstance(e, PluginError) for e in c.errors):
        return None, c.errors
    # Only plugins whose code raised: the config is whole (they are marked `broken`), and
    # `ramp run` may start the rest of the robot; every other caller sees the errors.
    cfg = Config(
        file=name,
        server=ServerConfig(**server, tls=tls),
        watchdog_timeout=wd["timeout"],
        rate_hz=sched["rate_hz"],
        stall_limit=sched["stall_limit"],
        idle_rate_hz=sched["idle_rate_hz"],
        buses=MappingProxyType(buses),
        modules=MappingProxyType(modules),
        recorder=recorder,
        lines=MappingProxyType({**_lines(root, "server"), **_lines(root, "recorder")}),
        interlocks=interlocks,
        access=access,
    )
    return cfg, list(c.errors)


def _access(c: _Checker, root: LinedMap, file: str,
            server: dict[str, Any]) -> tuple[TlsConfig | None, AccessConfig]:
    """`server.tls` and `access:` (SPEC 13); serving off loopback needs one of them."""
    raw_server = root.get("server")
    lines = raw_server.lines if isinstance(raw_server, LinedMap) else {}
    base = Path(file).resolve().parent if file else Path.cwd()
    raw_tls = raw_server.get("tls") if isinstance(raw_server, dict) else None
    tls = check_tls(raw_tls, lines.get("tls", root.lines.get("server", 1)), base, c.err)
    access = check_access(root.get("access"), root.lines.get("access", 1), c.err)
    problem = check_exposure(server["host"], tls if raw_tls is None else
                             (tls or TlsConfig("", "", "")), access)
    if problem is not None:
        c.err("server.host", lines.get("host", root.lines.get("server", 1)), problem)
    return tls, access


def _check_watchdog_tick(c: _Checker, root: LinedMap, timeout: float, rate_hz: float) -> None:
    """The watchdog is looked at once a tick: a timeout shorter than a tick (0.05 s at 1 Hz
    was accepted) would be noticed only up to a tick late, past what the file promises."""
    tick = 1.0 / rate_hz
    if timeout < tick:
        wd = root.get("watchdog")
        line = wd.lines.get("timeout", wd.line) if isinstance(wd, LinedMap) else 1
        c.err("watchdog.timeout", line,
              f"{timeout:g} s is shorter than one tick ({tick:g} s at scheduler.rate_hz "
              f"{rate_hz:g}): the watchdog is checked once a tick; raise the rate or the "
              "timeout")


def _report_bad_keys(c: _Checker, root: LinedMap) -> None:
    """A list or a mapping used as a key: reported where it is, then left out."""
    stack: list[tuple[Any, str]] = [(root, "")]
    while stack:
        node, path = stack.pop()
        if isinstance(node, LinedMap):
            for key in list(node):
                where = f"{path}.{key}" if path else str(key)
                if isinstance(key, BadKey):
                    c.err(path or "(top)", key.line,
                          f"a key must be a name, not {key.kind}")
                    del node[key]
                    continue
                stack.append((node[key], where))
        elif isinstance(node, list):
            stack.extend((v, f"{path}[{i}]") for i, v in enumerate(node))


def _check_host(c: _Checker, root: LinedMap, server: dict[str, Any]) -> None:
    host = server.get("host")
    raw = root.get("server")
    line = raw.lines.get("host", raw.line) if isinstance(raw, LinedMap) else 0
    if isinstance(host, str) and not valid_host(host):
        c.err("server.host", line, f"{shorten(repr(host), 60)} is not an IP address or host "
                                   "name (0.0.0.0 serves on every interface)")
        server["host"] = SERVER_FIELDS["host"].default


def _lines(root: LinedMap, section: str) -> dict[str, int]:
    """Lines of a section's keys, for errors found at run time (`server.max_clients`)."""
    raw = root.get(section)
    if not isinstance(raw, LinedMap):
        return {}
    return {f"{section}.{k}": line for k, line in raw.lines.items() if isinstance(k, str)}


def _recorder(c: _Checker, root: LinedMap, file: str) -> RecorderConfig | None:
    """`recorder: {dir, max_mb, keep}`: absent (or null) is off. A relative `dir` is
    relative to the config file's directory, as a path in a file is read by whoever reads
    the file (systemd starts the service in another working directory)."""
    if root.get("recorder") is None:
        return None
    values = c.block(root, "recorder", "recorder", RECORDER_FIELDS)
    raw = root["recorder"]
    if not isinstance(raw, LinedMap) or "dir" not in values:
        return None
    line = raw.lines.get("dir", raw.line)
    directory = values["dir"]
    if not directory.strip():
        c.err("recorder.dir", line, "'' is not a directory for the MCAP files")
        return None
    path = Path(directory).expanduser()
    if not path.is_absolute():
        path = Path(file).parent / path
    try:
        return RecorderConfig(str(path), values["max_mb"], values["keep"])
    except ConfigError as exc:  # what the block check cannot see (a NUL in `dir`)
        c.err(exc.key or "recorder", line, exc.detail)
        return None


def _buses(c: _Checker, root: LinedMap) -> tuple[dict[str, BusConfig], dict[str, type[Bus]]]:
    out: dict[str, BusConfig] = {}
    classes: dict[str, type[Bus]] = {}
    ports: dict[str, str] = {}
    raw = root.get("buses")
    if raw is None:
        return out, classes
    if not isinstance(raw, LinedMap):
        c.err("buses", root.lines.get("buses", 0), f"expected a mapping, got {kind_of(raw)}")
        return out, classes
    for dup, dline in raw.duplicates:
        c.err(f"buses.{dup}", dline, "bus given twice")
    for name, entry in raw.items():
        path = f"buses.{name}"
        line = raw.lines.get(name, raw.line)
        if not isinstance(entry, LinedMap):
            c.err(path, line, f"expected a mapping with a driver, got {kind_of(entry)}")
            continue
        driver = entry.get("driver")
        if not isinstance(driver, str) or len(driver) > 64:
            c.err(f"{path}.driver", entry.lines.get("driver", entry.line),
                  "missing; expected a driver name (sabertooth, phidget, can, sim)")
            continue
        try:
            cls = driver_class(driver)
        except PluginLoadError as exc:  # its code raised: `ramp run` starts the rest
            dline = entry.lines.get("driver", entry.line)
            c.plugin(f"{path}.driver", dline, str(exc))
            out[str(name)] = BusConfig(str(name), driver, MappingProxyType({}), True, line,
                                       broken=str(exc))
            continue
        except ValueError as exc:
            c.err(f"{path}.driver", entry.lines.get("driver", entry.line), str(exc))
            continue
        except ImportError as exc:
            c.err(f"{path}.driver", entry.lines.get("driver", entry.line),
                  f"driver {driver} cannot be loaded: {exc}")
            continue
        sim = entry.get("sim", True)
        if not isinstance(sim, bool):
            c.err(f"{path}.sim", entry.lines.get("sim", entry.line),
                  f"{shorten(repr(sim))} is not true or false")
            sim = True
        params = c.values(entry, path, dict(cls.fields), skip=BUS_COMMON)
        port = params.get("port")
        if isinstance(port, str):
            # A serial port has one owner: two buses on it would interleave their packets.
            other = ports.setdefault(port, str(name))
            if other != str(name):
                c.err(f"{path}.port", entry.lines.get("port", entry.line),
                      f"{port} is already the port of bus {other}; one bus per serial port "
                      "(several controllers share a port as addresses of one bus)")
        out[str(name)] = BusConfig(str(name), driver, MappingProxyType(params), sim, line)
        classes[str(name)] = cls
    return out, classes


def _modules(c: _Checker, root: LinedMap, buses: dict[str, BusConfig],
             bus_classes: dict[str, type[Bus]]) -> dict[str, ModuleConfig]:
    out: dict[str, ModuleConfig] = {}
    raw = root.get("modules")
    if raw is None:
        return out
    if not isinstance(raw, LinedMap):
        c.err("modules", root.lines.get("modules", 0), f"expected a mapping, got {kind_of(raw)}")
        return out
    used: dict[tuple[str, str, tuple[Any, ...]], str] = {}
    for name, entry in raw.items():
        path = f"modules.{name}"
        line = raw.lines.get(name, raw.line)
        if name == "robot":
            c.err(path, line, "`robot` is reserved for robot-level requests")
            continue
        if name == "sim":
            c.err(path, line, "`sim` is reserved for the simulator's fault injection "
                              "(SPEC 12, under --sim)")
            continue
        if not isinstance(name, str) or not MODULE_NAME.fullmatch(name):
            c.err(path, line, "a module name is 1-32 letters (A-Z, a-z), digits or _, since "
                              "clients address it over MCP (base:base.get=())")
            continue
        if not isinstance(entry, LinedMap):
            c.err(path, line, f"expected a mapping of devices, got {kind_of(entry)}")
            continue
        type_name = entry.get("type", name)
        try:
            cls = module_class(str(type_name))
        except PluginLoadError as exc:  # its code raised: `ramp run` starts the rest
            c.plugin(f"{path}.type", entry.lines.get("type", line), str(exc))
            out[str(name)] = ModuleConfig(str(name), str(type_name), MappingProxyType({}),
                                          MappingProxyType({}), entry.line, broken=str(exc))
            continue
        except ValueError as exc:
            c.err(f"{path}.type", entry.lines.get("type", line), str(exc))
            continue
        mod = _module(c, path, str(name), str(type_name), cls, entry, buses, bus_classes, used)
        if mod is not None:
            out[str(name)] = mod
    return out


def _module(c: _Checker, path: str, name: str, type_name: str, cls: type[Module],
            entry: LinedMap, buses: dict[str, BusConfig], bus_classes: dict[str, type[Bus]],
            used: dict[tuple[str, str, tuple[Any, ...]], str]) -> ModuleConfig | None:
    devices: dict[str, DeviceConfig] = {}
    settings: dict[str, Mapping[str, Any]] = {}
    for dup, dline in entry.duplicates:
        c.err(f"{path}.{dup}", dline, "key given twice")
    for key in entry:
        if key != "type" and key not in cls.devices and key not in cls.settings:
            expected = sorted([*cls.devices, *cls.settings, "type"])
            c.err(f"{path}.{key}", entry.lines.get(key, entry.line),
                  f"unknown device or setting for a {type_name} module (expected one of: "
                  f"{', '.join(expected)})")
    for block, fields in cls.settings.items():
        settings[block] = MappingProxyType(c.block(entry, block, f"{path}.{block}", fields))
    for dev, spec in cls.devices.items():
        dpath = f"{path}.{dev}"
        raw = entry.get(dev)
        dline = entry.lines.get(dev, entry.line)
        if raw is None:
            c.err(dpath, dline, f"missing; a {type_name} module needs a {spec.kind} device "
                                f"`{dev}` ({spec.help or 'see docs/operating/configuration.md'})")
            continue
        if not isinstance(raw, LinedMap):
            c.err(dpath, dline, f"expected a mapping with a bus, got {kind_of(raw)}")
            continue
        bus = raw.get("bus")
        if not isinstance(bus, str) or bus not in buses:
            known = ", ".join(sorted(buses)) or "none defined"
            c.err(f"{dpath}.bus", raw.lines.get("bus", raw.line),
                  f"{shorten(repr(bus))} is not a bus (known: {known})" if bus is not None
                  else f"missing; expected a bus name (known: {known})")
            continue
        bcls = bus_classes.get(bus)
        if bcls is None:  # its driver cannot be loaded (a PluginError): nothing to check
            devices[dev] = DeviceConfig(dev, bus, spec.kind, MappingProxyType({}),
                                        MappingProxyType({}), dline)
            continue
        if spec.kind not in bcls.channel_fields:
            c.err(f"{dpath}.bus", raw.lines.get("bus", raw.line),
                  f"bus {bus} (driver {bcls.driver_name}) has no {spec.kind} channels, which "
                  f"{dev} needs")
            continue
        ch_fields = bcls.channel_fields[spec.kind]
        # The driver's channel keys and the device's own, with the device's rules.
        all_fields = Block({**ch_fields, **spec.fields}, getattr(spec.fields, "rules", ()))
        values = c.values(raw, dpath, all_fields, skip={"bus"})
        channel = {k: values[k] for k in ch_fields if k in values}
        params = {k: values[k] for k in spec.fields if k in values}
        ident = (bus, spec.kind, tuple(sorted(channel.items())))
        if ch_fields and ident in used:
            c.err(dpath, dline, f"uses the same {spec.kind} channel of bus {bus} as "
                                f"{used[ident]}")
        used[ident] = f"{name}.{dev}"
        devices[dev] = DeviceConfig(dev, bus, spec.kind, MappingProxyType(channel),
                                    MappingProxyType(params), dline)
    broken = "; ".join(f"bus {b}: {buses[b].broken}" for b in
                       sorted({d.bus for d in devices.values()}) if buses[b].broken)
    return ModuleConfig(name, type_name, MappingProxyType(devices), MappingProxyType(settings),
                        entry.line, broken=broken)
