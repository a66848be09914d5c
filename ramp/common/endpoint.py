"""Where a client finds the robot, and how it proves who it is (SPEC 13).

`mcps://HOST:PORT` is MCP inside mutual TLS: the client checks the robot's certificate against
`--ca` and presents its own (`--cert` and `--key`, or one `--identity NAME.pem`, the bundle
`ramp certs issue` writes: certificate, key and CA in one file). A plain `HOST:PORT` (or
`mcp://HOST:PORT`) stays plain: loopback on the robot, or a development set-up.

Every client (`ramp-shell`, `ramp-teleop`, `ramp-autonomy`, `ramp-fleet-agent`) uses the same
flags and the same words when something is missing.
"""

from __future__ import annotations

import argparse
import ssl
from pathlib import Path

SCHEME_TLS = "mcps://"
SCHEME_PLAIN = "mcp://"


def split_scheme(text: str) -> tuple[bool, str]:
    """(`mcps://`?, the address without its scheme); ValueError for another scheme."""
    lowered = text.strip().lower()
    if lowered.startswith(SCHEME_TLS):
        return True, text.strip()[len(SCHEME_TLS):]
    if lowered.startswith(SCHEME_PLAIN):
        return False, text.strip()[len(SCHEME_PLAIN):]
    if "://" in text:
        raise ValueError(f"{text!r}: the scheme must be mcps:// (TLS) or mcp:// (plain)")
    return False, text


def add_tls_arguments(parser: argparse.ArgumentParser, what: str = "the robot") -> None:
    """`--cert`, `--key`, `--ca`, `--identity`: this client's identity for `mcps://`."""
    g = parser.add_argument_group(f"mutual TLS with {what} (an mcps:// address)")
    g.add_argument("--cert", metavar="FILE", help="this client's certificate (NAME.crt)")
    g.add_argument("--key", metavar="FILE", help="its private key (NAME.key)")
    g.add_argument("--ca", metavar="FILE", help="the robot's CA (ca.crt), to check the robot")
    g.add_argument("--identity", metavar="FILE",
                   help="one file with all three (NAME.pem from `ramp certs issue`)")


def client_context(*, cert: str | None = None, key: str | None = None, ca: str | None = None,
                   identity: str | None = None) -> ssl.SSLContext:
    """A client's side of mutual TLS; ValueError saying what is missing or wrong."""
    if identity is not None:
        cert = cert or identity
        ca = ca or identity
    missing = [flag for flag, value in (("--cert", cert), ("--ca", ca)) if not value]
    if missing:
        raise ValueError(f"an mcps:// address needs {' and '.join(missing)} (or --identity "
                         "NAME.pem from `ramp certs issue`)")
    assert cert is not None and ca is not None
    for flag, path in (("--cert", cert), ("--key", key), ("--ca", ca)):
        if path is not None and not Path(path).is_file():
            raise ValueError(f"{flag} {path}: no such file")
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    try:
        ctx.load_verify_locations(ca)
    except (ssl.SSLError, OSError) as exc:
        raise ValueError(f"--ca {ca}: not a CA certificate ({exc})") from None
    try:
        ctx.load_cert_chain(cert, key)
    except (ssl.SSLError, OSError) as exc:
        raise ValueError(f"--cert {cert}{f' --key {key}' if key else ''}: not a certificate "
                         f"and its key ({exc})") from None
    return ctx


def certificate_name(path: str | None) -> str | None:
    """The subject CN of the (first) certificate in a PEM file: the identity it proves
    (`ramp certs issue DIR NAME` makes CN = NAME); None when it cannot be read."""
    if path is None:
        return None
    try:
        from cryptography import x509
        from cryptography.x509.oid import NameOID

        cert = x509.load_pem_x509_certificate(Path(path).read_bytes())
    except (OSError, ValueError, ImportError):
        return None
    names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    value = names[0].value if names else None
    return value if isinstance(value, str) else None


def context_for(tls: bool, args: argparse.Namespace) -> ssl.SSLContext | None:
    """The context `add_tls_arguments`' flags ask for, None for a plain address (flags
    without `mcps://` are an error: a user who gave a certificate meant TLS)."""
    given = [f"--{name}" for name in ("cert", "key", "ca", "identity")
             if getattr(args, name, None)]
    if not tls:
        if given:
            raise ValueError(f"{', '.join(given)} given with a plain address: write "
                             "mcps://HOST:PORT for TLS")
        return None
    return client_context(cert=args.cert, key=args.key, ca=args.ca, identity=args.identity)
