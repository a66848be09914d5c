"""Certificates for the access tests (SPEC 13): a robot CA made by `ramp certs`, and the
ones an attacker or an accident brings (another CA's, expired, forged with the same CN)."""

from __future__ import annotations

import datetime as dt
import select
import socket
import ssl
from pathlib import Path
from typing import Any

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from ramp.certs.authority import create_ca, issue_client, issue_server, load_ca


def robot_pki(root: Path, clients: dict[str, str]) -> Path:
    """`root/robot`: the robot's CA, its server certificate for 127.0.0.1 and one client
    certificate per name of `clients`; also `root/other` (another CA and its `ana`)."""
    d = root / "robot"
    create_ca(d)
    issue_server(d, "robot", ["127.0.0.1", "localhost"])
    for name in clients:
        issue_client(d, name)
    other = root / "other"
    create_ca(other, "Someone else's CA")
    issue_client(other, "ana")
    return d


def expired_client(directory: Path, name: str) -> tuple[Path, Path]:
    """A certificate from the robot's own CA whose validity ended yesterday."""
    ca_cert, ca_key = load_ca(directory)
    key = ec.generate_private_key(ec.SECP256R1())
    now = dt.datetime.now(dt.UTC)
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca_cert.subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(days=30))
            .not_valid_after(now - dt.timedelta(days=1))
            .sign(ca_key, hashes.SHA256()))
    return _write(directory, f"{name}-expired", cert, key)


def forged_client(directory: Path, name: str) -> tuple[Path, Path]:
    """Self-signed, with the CN of a real identity: a stranger posing as `name`."""
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    now = dt.datetime.now(dt.UTC)
    cert = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(days=1))
            .not_valid_after(now + dt.timedelta(days=30)).sign(key, hashes.SHA256()))
    return _write(directory, f"{name}-forged", cert, key)


def serial_of(crt: Path) -> int:
    return x509.load_pem_x509_certificate(crt.read_bytes()).serial_number


def _write(directory: Path, stem: str, cert: x509.Certificate,
           key: ec.EllipticCurvePrivateKey) -> tuple[Path, Path]:
    crt, key_path = directory / f"{stem}.crt", directory / f"{stem}.key"
    crt.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM,
                                           serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    return crt, key_path


def client_context(ca: Path, crt: Path | None = None, key: Path | None = None) -> ssl.SSLContext:
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.load_verify_locations(ca)
    if crt is not None and key is not None:
        ctx.load_cert_chain(crt, key)
    return ctx


def tls_handshake(sock: socket.socket, ctx: ssl.SSLContext, pump: Any,
                  polls: int = 4000) -> ssl.SSLSocket:
    """Shake hands without blocking while `pump()` turns the server's loop (the tests'
    supervisor runs in this thread). Raises what the handshake raises."""
    sock.setblocking(False)
    tls = ctx.wrap_socket(sock, server_hostname="127.0.0.1", do_handshake_on_connect=False)
    for _ in range(polls):
        try:
            tls.do_handshake()
            return tls
        except (ssl.SSLWantReadError, ssl.SSLWantWriteError):
            pump()
            select.select([tls], [], [], 0.001)
    raise TimeoutError("handshake did not finish")
