"""The one `HOST:PORT` parser, for every command line and file that names a TCP peer.

    robot.local:5577   10.0.0.2:5577   [::1]:5577   [fe80::1]   ::1   :5577   5577   host

Which short forms are allowed is the caller's choice: with a `default_port` the port may be
left out (`host`, `host:`, `[::1]`, a bare IPv6 address); with a `default_host` the host may
(`:5577`, `5577`). An IPv6 address with a port must be in brackets (`fe80::1:5577` could be
either). Every refusal is a ValueError whose text says what was given, what is wrong and
what was expected, fit for a command line or a config error.
"""

from __future__ import annotations

import ipaddress
import re

DEFAULT_EXAMPLE = "192.168.0.20:5577"


def parse_hostport(text: str, *, default_host: str | None = None,
                   default_port: int | None = None,
                   example: str = DEFAULT_EXAMPLE) -> tuple[str, int]:
    """`HOST:PORT` -> (host, port), IPv6 hosts without their brackets; ValueError says why."""

    def bad(reason: str) -> ValueError:
        return ValueError(f"{text!r}: {reason}; expected HOST:PORT (for example {example})")

    text = text.strip()
    if not text:
        if default_host is not None and default_port is not None:
            return default_host, default_port
        raise ValueError(f"empty address; expected HOST:PORT (for example {example})")
    if text.startswith("["):
        close = text.find("]")
        if close < 0:
            raise bad("unclosed '[' in an IPv6 address")
        host, rest = text[1:close], text[close + 1:]
        if not host:
            raise bad("empty host in brackets")
        if rest and not rest.startswith(":"):
            raise bad("expected ':' after ']', as in [ADDRESS]:PORT")
        port_text = rest[1:]
    elif text.isdigit() and default_host is not None:
        host, port_text = default_host, text
    elif text.count(":") == 1:
        host, _, port_text = text.partition(":")
    elif ":" in text:
        if _is_ipv6(text) and default_port is not None:
            return text, default_port
        raise bad("an IPv6 address with a port goes in brackets, as in [ADDRESS]:PORT")
    else:
        host, port_text = text, ""
    if not host:
        if default_host is None:
            raise bad("no host")
        host = default_host
    if any(c.isspace() or not c.isprintable() for c in host):
        raise bad(f"{host!r} is not a host name or address")
    if not port_text:
        if default_port is None:
            raise bad("no port")
        return host, default_port
    if not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise bad(f"port {port_text!r} is not a port number 1-65535")
    return host, int(port_text)


_HOST_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?")


def valid_host(host: str) -> bool:
    """An IPv4 or IPv6 address, or a host name (letters, digits, `-`, dots between labels).
    Four numbers that are not an IPv4 address (999.1.1.1) are neither."""
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        pass
    name = host[:-1] if host.endswith(".") else host
    labels = name.split(".")
    if not name or len(name) > 253 or all(label.isdigit() for label in labels):
        return False
    return all(_HOST_LABEL.fullmatch(label) for label in labels)


def format_hostport(host: str, port: int) -> str:
    """(host, port) -> `host:port`, an IPv6 host in brackets."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def _is_ipv6(text: str) -> bool:
    try:
        ipaddress.IPv6Address(text.split("%", 1)[0])
    except ValueError:
        return False
    return True
