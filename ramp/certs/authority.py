"""A robot's small certificate authority: the CA, the robot's server certificate and one
certificate per client identity (SPEC 13, `ramp certs`).

Everything cryptographic is pyca/cryptography's; this file only chooses the fields. Keys are
ECDSA P-256 (small, fast to sign and verify on a single-board computer, accepted by every TLS
stack RAMP meets: CPython's ssl, Chromium, Mosquitto). Private keys are written mode 0600 and
never overwritten: a CA that already exists is an error, so a second `init` cannot silently
orphan every certificate issued before it.

Files, all PEM, in one directory: `ca.crt`, `ca.key`, `NAME.crt`, `NAME.key` and, for a
client, `NAME.pem` (its certificate, its key and the CA in one file: `--identity NAME.pem`).
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

#: What a certificate name may be: an MCP name (it becomes the identity that acquires control,
#: SPEC 2.2) and a file name.
NAME = re.compile(r"[A-Za-z0-9_-]{1,32}")
CA_DAYS = 3650
LEAF_DAYS = 825  # the longest validity browsers accept for a server certificate


class CertError(Exception):
    """A certificate operation that cannot be done, with what to do about it."""


@dataclass(frozen=True)
class CertInfo:
    """What `ramp certs list` shows of one certificate."""

    path: Path
    common_name: str
    serial: int
    not_after: dt.datetime
    issuer: str
    kind: str  # "ca", "server", "client"


def check_name(name: str) -> str:
    if not NAME.fullmatch(name):
        raise CertError(f"{name!r} is not a certificate name (1-32 letters, digits, _ or -)")
    if name in ("ca", "robot") or name.lower() == "none":
        raise CertError(f"{name!r} is reserved (the CA, the robot's own certificate, none)")
    return name


def create_ca(directory: Path, common_name: str = "RAMP CA", days: int = CA_DAYS) -> None:
    """Write `ca.crt` and `ca.key` in `directory` (made if missing); refuse to overwrite."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    crt, key_path = directory / "ca.crt", directory / "ca.key"
    for path in (crt, key_path):
        if path.exists():
            raise CertError(f"{path} already exists: this directory has a CA (issue "
                            "certificates with it, or choose another directory)")
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])
    now = _now()
    cert = (x509.CertificateBuilder()
            .subject_name(name).issuer_name(name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5))
            .not_valid_after(now + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(
                digital_signature=True, key_cert_sign=True, crl_sign=True,
                content_commitment=False, key_encipherment=False, data_encipherment=False,
                key_agreement=False, encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                           critical=False)
            .sign(key, hashes.SHA256()))
    _write_key(key_path, key)
    crt.write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def issue_server(directory: Path, name: str, hosts: Sequence[str],
                 days: int = LEAF_DAYS) -> tuple[Path, Path]:
    """`NAME.crt`/`NAME.key` for a server (the robot, a broker) reachable as `hosts` (names
    and IP addresses, put in its subjectAltName), signed by the CA in `directory`."""
    if not hosts:
        raise CertError("a server certificate needs at least one --host (the name or address "
                        "clients connect to)")
    sans: list[x509.GeneralName] = []
    for host in hosts:
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(host.strip("[]"))))
        except ValueError:
            if not re.fullmatch(r"[A-Za-z0-9*]([A-Za-z0-9.-]{0,251}[A-Za-z0-9])?", host):
                raise CertError(f"{host!r} is neither an IP address nor a host name") from None
            sans.append(x509.DNSName(host))
    return _issue(Path(directory), name, days, sans, ExtendedKeyUsageOID.SERVER_AUTH)


def issue_client(directory: Path, name: str, days: int = LEAF_DAYS) -> tuple[Path, Path]:
    """`NAME.crt`/`NAME.key` (CN = NAME, the identity) and the `NAME.pem` bundle for a client,
    signed by the CA in `directory`."""
    check_name(name)
    crt, key = _issue(Path(directory), name, days, [], ExtendedKeyUsageOID.CLIENT_AUTH)
    bundle = Path(directory) / f"{name}.pem"
    _write_private(bundle, crt.read_bytes() + key.read_bytes()
                   + (Path(directory) / "ca.crt").read_bytes())
    return crt, key


def _issue(directory: Path, name: str, days: int, sans: list[x509.GeneralName],
           usage: x509.ObjectIdentifier) -> tuple[Path, Path]:
    if not NAME.fullmatch(name):
        raise CertError(f"{name!r} is not a certificate name (1-32 letters, digits, _ or -)")
    ca_cert, ca_key = load_ca(directory)
    crt, key_path = directory / f"{name}.crt", directory / f"{name}.key"
    if crt.exists() or key_path.exists():
        raise CertError(f"{crt} already exists: revoke it (its serial in access.revoked) and "
                        "issue under another name, or remove the old files first")
    key = ec.generate_private_key(ec.SECP256R1())
    now = _now()
    builder = (x509.CertificateBuilder()
               .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
               .issuer_name(ca_cert.subject)
               .public_key(key.public_key())
               .serial_number(x509.random_serial_number())
               .not_valid_before(now - dt.timedelta(minutes=5))
               .not_valid_after(now + dt.timedelta(days=days))
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
               .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(
                   ca_key.public_key()), critical=False))
    if sans:
        builder = builder.add_extension(x509.SubjectAlternativeName(sans), critical=False)
    cert = builder.sign(ca_key, hashes.SHA256())
    _write_key(key_path, key)
    crt.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return crt, key_path


def load_ca(directory: Path) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    crt, key_path = Path(directory) / "ca.crt", Path(directory) / "ca.key"
    if not crt.exists() or not key_path.exists():
        raise CertError(f"no CA in {directory} (ca.crt and ca.key): run `ramp certs init "
                        f"{directory} --host ROBOT_NAME_OR_IP` first")
    cert = x509.load_pem_x509_certificate(crt.read_bytes())
    key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise CertError(f"{key_path} is not an EC key made by `ramp certs init`")
    return cert, key


def list_certificates(directory: Path) -> list[CertInfo]:
    """Every `*.crt` in `directory`, the CA first."""
    out = []
    for path in sorted(Path(directory).glob("*.crt"), key=lambda p: (p.stem != "ca", p.stem)):
        try:
            cert = x509.load_pem_x509_certificate(path.read_bytes())
        except ValueError:
            continue
        out.append(CertInfo(path, _cn(cert.subject), cert.serial_number,
                            cert.not_valid_after_utc, _cn(cert.issuer), _kind(cert)))
    return out


def _kind(cert: x509.Certificate) -> str:
    try:
        if cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca:
            return "ca"
    except x509.ExtensionNotFound:
        pass
    try:
        usages = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    except x509.ExtensionNotFound:
        return "client"
    return "server" if ExtendedKeyUsageOID.SERVER_AUTH in usages else "client"


def _cn(name: x509.Name) -> str:
    attrs = name.get_attributes_for_oid(NameOID.COMMON_NAME)
    value = attrs[0].value if attrs else ""
    return value if isinstance(value, str) else value.decode(errors="replace")


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def _write_key(path: Path, key: ec.EllipticCurvePrivateKey) -> None:
    _write_private(path, key.private_bytes(serialization.Encoding.PEM,
                                           serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))


def _write_private(path: Path, data: bytes) -> None:
    """Created 0600 from the start (never world-readable, not even for a moment)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.write(fd, data)
    finally:
        os.close(fd)
    os.chmod(path, 0o600)
