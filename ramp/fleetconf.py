"""The `fleet:` block of `ramp.yaml` (SPEC 14): its keys and their one check.

Two readers, which may not import each other: the config loader (`ramp check`, `ramp run`,
which only check the block so a mistake shows before the robot runs) and the fleet agent
(`ramp-fleet-agent`, which uses it). The block lives here, beside neither, on `ramp.schema`.

    fleet:
      manufacturer: RAMP        # topic and header field (default RAMP)
      serial: marte-1           # topic and header serialNumber (required)
      broker: 10.0.0.5:8883     # the MQTT broker (required)
      tls: {ca: certs/ca.crt, cert: certs/marte-1.crt, key: certs/marte-1.key}
      autonomy: 127.0.0.1:5590  # the autonomy's command endpoint: a robot with the autonomy
      state_dir: /var/lib/ramp  # where the fleet's pause is kept (default: as ramp run's)
      series: MARTE             # the factsheet: series name, top speed (m/s), size (m)
      speed_max: 0.5
      length: 1.2
      width: 0.75
      height: 0.8

Paths are relative to the config file's directory. `problems(raw)` returns
(key, line, message) for each mistake; `parse(raw, base_dir)` the checked `FleetConfig`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ramp.common.hostport import parse_hostport
from ramp.schema import Field, validate

#: A topic level MQTT and VDA 5050 both accept: no `/`, `+`, `#`, spaces or control bytes.
NAME = re.compile(r"[A-Za-z0-9_.-]{1,64}")

FLEET_FIELDS: dict[str, Field] = {
    "manufacturer": Field(str, "RAMP", what="a name of 1-64 letters, digits, _ . -"),
    "serial": Field(str, what="a serial of 1-64 letters, digits, _ . - (the robot's name)"),
    "broker": Field(str, what="the broker's HOST:PORT (for example 10.0.0.5:8883)"),
    "tls": Field(dict, None, what="a mapping {ca, cert, key}"),
    "autonomy": Field(str, None, what="the autonomy's command endpoint HOST:PORT"),
    "state_dir": Field(str, None, what="a directory"),
    # The factsheet's description of the robot (VDA 5050 typeSpecification, physicalParameters).
    "series": Field(str, "RAMP robot", what="the robot's series name"),
    "speed_max": Field(float, 0.5, lo=0.0, hi=20.0, what="the top speed in m/s"),
    "length": Field(float, 1.2, lo=0.0, hi=20.0, what="the robot's length in m"),
    "width": Field(float, 0.75, lo=0.0, hi=20.0, what="the robot's width in m"),
    "height": Field(float, 0.8, lo=0.0, hi=20.0, what="the robot's height in m"),
}
TLS_FIELDS: dict[str, Field] = {
    "ca": Field(str, what="the CA certificate file that signed the broker's certificate"),
    "cert": Field(str, what="this robot's certificate file (CN = its serial)"),
    "key": Field(str, what="this robot's private key file"),
}


@dataclass(frozen=True)
class FleetTls:
    ca: Path
    cert: Path
    key: Path


@dataclass(frozen=True)
class FleetConfig:
    manufacturer: str
    serial: str
    broker: tuple[str, int]
    tls: FleetTls | None = None
    autonomy: tuple[str, int] | None = None
    state_dir: Path | None = None
    series: str = "RAMP robot"
    speed_max: float = 0.5
    size: tuple[float, float, float] = (1.2, 0.75, 0.8)  # length, width, height in m


def _line(raw: Any, key: str) -> int:
    lines = getattr(raw, "lines", {})
    return int(lines.get(key, getattr(raw, "line", 0)))


def problems(raw: Any, path: str = "fleet") -> list[tuple[str, int, str]]:
    """Every mistake in a `fleet:` block as (key path, line, message); [] when it is good."""
    here = getattr(raw, "line", 0)
    if not isinstance(raw, Mapping):
        return [(path, here, "expected a mapping {manufacturer, serial, broker, ...}")]
    found: list[tuple[str, int, str]] = []
    values, bad = validate(FLEET_FIELDS, raw)
    for key, message in bad:
        found.append((f"{path}.{key}" if key else path, _line(raw, key), message))
    for key in ("manufacturer", "serial"):
        value = values.get(key)
        if isinstance(value, str) and key in raw and not NAME.fullmatch(value):
            found.append((f"{path}.{key}", _line(raw, key),
                          f"{value!r} is not {FLEET_FIELDS[key].expected()}"))
    for key in ("broker", "autonomy"):
        value = values.get(key)
        if isinstance(value, str) and key in raw:
            try:
                parse_hostport(value)
            except ValueError as exc:
                found.append((f"{path}.{key}", _line(raw, key), str(exc)))
    tls = raw.get("tls")
    if isinstance(tls, Mapping):
        _, bad = validate(TLS_FIELDS, tls)
        found += [(f"{path}.tls.{k}" if k else f"{path}.tls", _line(tls, k), m) for k, m in bad]
    return found


def parse(raw: Any, base_dir: Path) -> FleetConfig:
    """The checked block; ValueError listing the problems as `line: key: message`."""
    bad = problems(raw)
    if bad:
        raise ValueError("; ".join(f"line {line}: {key}: {msg}" for key, line, msg in bad))
    values, _ = validate(FLEET_FIELDS, raw)
    tls = None
    if values["tls"] is not None:
        t, _ = validate(TLS_FIELDS, values["tls"])
        tls = FleetTls(*(base_dir / t[k] for k in ("ca", "cert", "key")))
    autonomy = parse_hostport(values["autonomy"]) if values["autonomy"] else None
    return FleetConfig(values["manufacturer"], values["serial"],
                       parse_hostport(values["broker"]), tls, autonomy,
                       base_dir / values["state_dir"] if values["state_dir"] else None,
                       values["series"], values["speed_max"],
                       (values["length"], values["width"], values["height"]))
