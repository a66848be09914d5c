"""Who may command the robot (SPEC 13): the roles, the policy's shape, what loopback is,
and the robot's side of mutual TLS. Standard library only: the server, the config check and
the clients share it (`ramp.config.access` checks the YAML into these)."""

from __future__ import annotations

import ipaddress
import re
import ssl
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

#: Roles, weakest first (SPEC 13). `none` is only for `access.local`: plain loopback refused.
ROLES = ("none", "observer", "operator", "admin")
RANK = {name: i for i, name in enumerate(ROLES)}
IDENTITY = re.compile(r"[A-Za-z0-9_-]{1,32}")


@dataclass(frozen=True)
class TlsConfig:
    """Absolute paths of the robot's certificate, key and the client CA."""

    cert: str
    key: str
    client_ca: str


@dataclass(frozen=True)
class AccessConfig:
    """The access policy. `configured` is False when the file has no `access:` section:
    then plain loopback clients are `admin` (development, tests, `make run`)."""

    configured: bool = False
    local: str = "admin"
    identities: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    revoked: frozenset[int] = frozenset()
    max_per_identity: int = 4
    max_per_address: int = 6
    allow_anonymous: bool = False

    def role_of(self, identity: str) -> str | None:
        return self.identities.get(identity)


def is_loopback(host: str) -> bool:
    """A listening or peer address only this machine can reach."""
    if host.lower() in ("localhost", "localhost."):
        return True
    try:
        addr = ipaddress.ip_address(host.strip("[]").split("%")[0])
    except ValueError:
        return False
    if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is not None:
        addr = addr.ipv4_mapped
    return addr.is_loopback


def server_context(tls: TlsConfig) -> ssl.SSLContext:
    """The robot's side of mutual TLS: its certificate, client certificates required and
    verified against `client_ca` (validity dates included), TLS 1.2 at least."""
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    ctx.load_cert_chain(tls.cert, tls.key)
    ctx.load_verify_locations(tls.client_ca)
    ctx.verify_mode = ssl.CERT_REQUIRED
    return ctx
