"""`server.tls` and `access:` (SPEC 13): who may command the robot, checked like the rest of
`ramp.yaml` (every problem at its file:line:key, saying what to do).

The rule a field robot needs: MCP is served off loopback only with TLS client
authentication, or with an explicit, loudly-warned `access.allow_anonymous: true`. With no
`access:` section at all every (necessarily loopback) client is `admin`, as in development.
"""

from __future__ import annotations

import ssl
from collections.abc import Callable
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ramp.common.access import (
    IDENTITY,
    ROLES,
    AccessConfig,
    TlsConfig,
    is_loopback,
    server_context,
)
from ramp.common.yamlload import LinedMap, kind_of
from ramp.schema import Field, shorten, validate

ACCESS_FIELDS = {
    "local": Field(str, "operator", choices=ROLES, what="a role for plain loopback clients"),
    "identities": Field(dict, {}, what="a mapping of certificate CN to role"),
    "revoked": Field(list, [], what="a list of certificate serials"),
    "max_per_identity": Field(int, 4, lo=1, hi=4096, what="connections per identity"),
    "max_per_address": Field(int, 6, lo=1, hi=4096, what="connections per remote address"),
    "allow_anonymous": Field(bool, False),
}
TLS_FIELDS = {
    "cert": Field(str, what="the robot's certificate (PEM file)"),
    "key": Field(str, what="the robot's private key (PEM file)"),
    "client_ca": Field(str, what="the CA that signs client certificates (PEM file)"),
}

Err = Callable[[str, int, str], None]


def check_tls(raw: Any, line: int, base: Path, err: Err) -> TlsConfig | None:
    """`server.tls: {cert, key, client_ca}`; paths relative to the config file. The files
    are loaded here, so `ramp check` finds a wrong key or a missing file."""
    if raw is None:
        return None
    if not isinstance(raw, dict):
        err("server.tls", line, f"expected a mapping {{cert, key, client_ca}}, got {kind_of(raw)}")
        return None
    lines = {str(k): v for k, v in getattr(raw, "lines", {}).items()}
    values, problems = validate(TLS_FIELDS, raw)
    for key, message in problems:
        err(f"server.tls.{key}" if key else "server.tls", lines.get(key, line), message)
    if problems:
        return None
    paths = {k: str((base / v).resolve()) if not Path(v).is_absolute() else v
             for k, v in values.items()}
    for key, path in paths.items():
        if not Path(path).is_file():
            err(f"server.tls.{key}", lines.get(key, line),
                f"{shorten(path, 120)} does not exist (make the robot's certificates with "
                "`ramp certs init DIR --host NAME_OR_IP`)")
            return None
    tls = TlsConfig(**paths)
    try:
        server_context(tls)
    except (ssl.SSLError, OSError) as exc:
        err("server.tls", line, f"cannot load the certificate, key or client CA: {exc}")
        return None
    return tls


def check_access(raw: Any, line: int, err: Err) -> AccessConfig:
    """The `access:` section (absent: not configured, loopback clients admin)."""
    if raw is None:
        return AccessConfig()
    if not isinstance(raw, dict):
        err("access", line, f"expected a mapping, got {kind_of(raw)}")
        return AccessConfig(configured=True, local="operator")
    lines = {str(k): v for k, v in getattr(raw, "lines", {}).items()}
    values, problems = validate(ACCESS_FIELDS, raw)
    for key, message in problems:
        err(f"access.{key}" if key else "access", lines.get(key, line), message)
    identities = _identities(raw.get("identities"), lines.get("identities", line), err)
    revoked = _serials(raw.get("revoked"), lines.get("revoked", line), err)
    return AccessConfig(True, values["local"], MappingProxyType(identities), revoked,
                        values["max_per_identity"], values["max_per_address"],
                        values["allow_anonymous"])


def _identities(raw: Any, line: int, err: Err) -> dict[str, str]:
    out: dict[str, str] = {}
    if not isinstance(raw, dict):
        return out
    lines = raw.lines if isinstance(raw, LinedMap) else {}
    for name, role in raw.items():
        where = lines.get(name, line)
        if not isinstance(name, str) or not IDENTITY.fullmatch(name) or name == "none":
            err(f"access.identities.{name}", where,
                f"{shorten(repr(name), 40)} is not an identity (a certificate CN of 1-32 "
                "letters, digits, _ or -; none is reserved)")
        elif role not in ROLES[1:]:
            err(f"access.identities.{name}", where,
                f"{shorten(repr(role), 40)} is not a role (observer, operator or admin)")
        else:
            out[name] = role
    return out


def _serials(raw: Any, line: int, err: Err) -> frozenset[int]:
    out: set[int] = set()
    if not isinstance(raw, list):
        return frozenset()
    for i, value in enumerate(raw):
        serial: int | None = None
        if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
            serial = value
        elif isinstance(value, str):
            text = value.strip().lower().replace(":", "")
            try:
                serial = int(text, 16) if text.startswith("0x") else int(text, 10)
            except ValueError:
                serial = None
        if serial is None:
            err(f"access.revoked[{i}]", line,
                f"{shorten(repr(value), 60)} is not a certificate serial (decimal, or 0x hex "
                "as `ramp certs list` prints it)")
        else:
            out.add(serial)
    return frozenset(out)


def check_exposure(host: str, tls: TlsConfig | None, access: AccessConfig) -> str | None:
    """Why serving on `host` is refused (SPEC 13: off loopback only with TLS client
    authentication, or explicitly anonymous), or None."""
    if tls is not None or access.allow_anonymous or is_loopback(host):
        return None
    return (f"{host} serves MCP beyond this machine with no authentication: anyone on the "
            "network could drive the robot. Add server.tls (`ramp certs init DIR --host "
            "NAME_OR_IP`, see docs/operating/security.md), serve on 127.0.0.1, or set "
            "access.allow_anonymous: true to accept that risk")
