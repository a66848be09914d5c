"""`ramp certs` (SPEC 13): the files the robot's TLS and its clients need, made with
pyca/cryptography, keys never readable by others, and a CA never overwritten."""

from __future__ import annotations

import ipaddress
import ssl
import stat
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from ramp.certs.authority import CertError, create_ca, issue_client, list_certificates
from ramp.cli import main


def _cert(path: Path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def test_init_issue_and_list(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = tmp_path / "certs"
    assert main(["certs", "init", str(d), "--host", "192.168.1.20", "--host", "marte.local"]) == 0
    assert {p.name for p in d.iterdir()} == {"ca.crt", "ca.key", "robot.crt", "robot.key"}
    robot = _cert(d / "robot.crt")
    sans = robot.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert ipaddress.ip_address("192.168.1.20") in sans.get_values_for_type(x509.IPAddress)
    assert sans.get_values_for_type(x509.DNSName) == ["marte.local"]
    assert main(["certs", "issue", str(d), "console-ana", "--role", "observer"]) == 0
    out = capsys.readouterr().out
    assert "    console-ana: observer" in out.splitlines()
    client = _cert(d / "console-ana.crt")
    assert client.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == "console-ana"
    usage = client.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    assert ExtendedKeyUsageOID.CLIENT_AUTH in usage
    assert client.issuer == _cert(d / "ca.crt").subject
    for key in ("ca.key", "robot.key", "console-ana.key", "console-ana.pem"):
        assert stat.S_IMODE((d / key).stat().st_mode) == 0o600, key
    assert f"serial {client.serial_number:#x}" in out
    assert main(["certs", "list", str(d)]) == 0
    listing = capsys.readouterr().out
    assert f"serial={client.serial_number:#x}" in listing and "CN=console-ana" in listing
    assert [c.kind for c in list_certificates(d)] == ["ca", "client", "server"]


def test_the_bundle_is_a_working_client_identity(tmp_path: Path) -> None:
    """NAME.pem holds the certificate, its key and the CA: one file for `--identity`."""
    create_ca(tmp_path)
    issue_client(tmp_path, "trainer")
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.load_cert_chain(tmp_path / "trainer.pem")
    ctx.load_verify_locations(tmp_path / "trainer.pem")
    assert len(ctx.get_ca_certs()) == 1


def test_nothing_is_overwritten_and_names_are_checked(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["certs", "init", str(tmp_path), "--host", "127.0.0.1"]) == 0
    before = (tmp_path / "ca.key").read_bytes()
    assert main(["certs", "init", str(tmp_path), "--host", "127.0.0.1"]) == 1
    assert "already exists" in capsys.readouterr().err
    assert (tmp_path / "ca.key").read_bytes() == before
    for bad in ("no spaces", "robot", "none", "x" * 33):
        with pytest.raises(CertError):
            issue_client(tmp_path, bad)
    issue_client(tmp_path, "ana")
    assert main(["certs", "issue", str(tmp_path), "ana"]) == 1
    assert main(["certs", "issue", str(tmp_path / "nowhere"), "bob"]) == 1
    assert "ramp certs init" in capsys.readouterr().err
