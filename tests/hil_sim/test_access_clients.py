"""Every client speaks mutual TLS (SPEC 13): `mcps://HOST:PORT` with `--cert/--key/--ca` or
one `--identity` bundle, against a real `ramp run --sim` serving TLS; a robot whose
certificate the client's CA did not sign is refused with words a user can act on."""

from __future__ import annotations

import asyncio
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from ramp.certs.authority import create_ca, issue_client, issue_server
from ramp.common.endpoint import client_context, context_for, split_scheme
from ramp.common.tcpclient import TcpClient
from ramp.mcp.aio import AsyncMcpClient
from ramp.mcp.client import McpClient
from tests.harness import MARTE_YAML, start_ramp, stop_process


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("pki")
    create_ca(d)
    issue_server(d, "robot", ["127.0.0.1"])
    for name in ("ana", "autonomy", "fleet"):
        issue_client(d, name)
    other = d / "other"
    create_ca(other, "another robot's CA")
    return d


@pytest.fixture(scope="module")
def robot(pki: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[int]:
    """MARTE on its emulators, MCP on every interface over mutual TLS."""
    secure = (f"server: {{host: 0.0.0.0, port: 0, tls: {{cert: {pki}/robot.crt, "
              f"key: {pki}/robot.key, client_ca: {pki}/ca.crt}}}}\n"
              "access: {local: operator, identities: {ana: operator, autonomy: operator, "
              "fleet: operator}}")
    text = "\n".join(secure if line.startswith("server:") else line
                     for line in MARTE_YAML.splitlines())
    config = tmp_path_factory.mktemp("robot") / "robot.yaml"
    config.write_text(text)
    proc, _, port = start_ramp(["--sim", "--config", str(config)])
    yield port
    stop_process(proc)
    proc.communicate()


def shell(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "ramp.shell.cli", *args], capture_output=True,
                          text=True, timeout=30)


def test_ramp_shell_with_cert_key_and_ca(robot: int, pki: Path) -> None:
    proc = shell(f"mcps://127.0.0.1:{robot}", "--cert", str(pki / "ana.crt"), "--key",
                 str(pki / "ana.key"), "--ca", str(pki / "ca.crt"), "--raw",
                 "-c", "robot:robot.get=()")
    assert proc.returncode == 0, proc.stderr
    assert "robot:access.me=(ana,operator)" in proc.stdout


def test_ramp_shell_with_one_identity_bundle(robot: int, pki: Path) -> None:
    proc = shell(f"mcps://127.0.0.1:{robot}", "--identity", str(pki / "ana.pem"), "--raw",
                 "-c", "robot:control.acquire=(ana)robot:robot.get=()")
    assert proc.returncode == 0, proc.stderr
    assert "robot:control.owner=(ana)" in proc.stdout


def test_a_robot_the_client_does_not_trust_is_refused_in_words(robot: int, pki: Path) -> None:
    proc = shell(f"mcps://127.0.0.1:{robot}", "--cert", str(pki / "ana.crt"), "--key",
                 str(pki / "ana.key"), "--ca", str(pki / "other" / "ca.crt"),
                 "-c", "robot:robot.get=()")
    assert proc.returncode == 2
    assert "certificate is not trusted" in proc.stderr and "--ca" in proc.stderr


def test_usage_errors_name_the_flag(pki: Path) -> None:
    proc = shell("127.0.0.1:5577", "--identity", str(pki / "ana.pem"), "-c", "x")
    assert proc.returncode == 2 and "mcps://" in proc.stderr
    proc = shell("mcps://127.0.0.1:5577", "-c", "x")
    assert proc.returncode == 2 and "--cert and --ca" in proc.stderr
    proc = shell("mcps://127.0.0.1:5577", "--identity", str(pki / "nobody.pem"), "-c", "x")
    assert proc.returncode == 2 and "no such file" in proc.stderr
    with pytest.raises(ValueError, match="mcps:// .TLS. or mcp://"):
        split_scheme("https://robot:5577")


def test_the_blocking_and_the_asyncio_clients(robot: int, pki: Path) -> None:
    ctx = client_context(identity=str(pki / "ana.pem"))
    with McpClient("127.0.0.1", robot, ssl_context=ctx) as c:
        c.send("robot:robot.get=()")
        assert "robot:access.me=(ana,operator)" in c.recv_line().decode()

    async def teleop_link() -> str:
        client = await AsyncMcpClient.connect("127.0.0.1", robot, ssl_context=ctx)
        try:
            return " ".join(str(r) for r in await client.request("robot:robot.get=()"))
        finally:
            await client.close()

    assert "ana" in asyncio.run(teleop_link())


def test_the_non_blocking_client_of_the_autonomy_and_the_fleet_agent(robot: int,
                                                                       pki: Path) -> None:
    """The loop-driven client (autonomy link, fleet agent link): connect and handshake
    without blocking, then MCP as usual, including bytes TLS buffers past a poll."""
    got = bytearray()
    ctx = client_context(identity=str(pki / "autonomy.pem"))
    c = TcpClient("127.0.0.1", robot, now=time.monotonic, ssl_context=ctx,
                  on_data=lambda data, now: got.extend(data))
    c.start()
    deadline = time.monotonic() + 10
    while not c.connected and time.monotonic() < deadline:
        c.tick(time.monotonic())
        time.sleep(0.002)
    assert c.connected
    assert c.write(b"robot:robot.get=()\n" * 20)
    while got.count(b"\n") < 20 and time.monotonic() < deadline:
        c.tick(time.monotonic())
        time.sleep(0.002)
    lines = bytes(got).splitlines()
    assert len(lines) == 20 and all(b"robot:access.me=(autonomy,operator)" in x for x in lines)
    c.close()


def test_the_autonomy_must_be_named_autonomy(pki: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "ramp.autonomy.cli", "--backend",
                           "mcps://127.0.0.1:5577", "--identity", str(pki / "ana.pem")],
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2
    assert "ramp certs issue DIR autonomy" in proc.stderr


def test_flags_without_mcps_are_refused() -> None:
    import argparse

    args = argparse.Namespace(cert="a.crt", key=None, ca=None, identity=None)
    with pytest.raises(ValueError, match="plain address"):
        context_for(False, args)


def test_the_console_takes_control_under_its_certificate_s_name(pki: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "ramp.teleop.cli", "--backend",
                           "mcps://127.0.0.1:5577", "--identity", str(pki / "ana.pem"),
                           "--name", "operator"], capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2
    assert "only under this console's identity, ana" in proc.stderr


def test_the_live_view_off_loopback_needs_tls_and_serves_wss(pki: Path) -> None:
    """SPEC 13: the read-only live view listens beyond loopback only over wss://."""
    import ssl

    from websockets.sync.client import connect

    from ramp.autonomy.live import FoxgloveLive, LiveViewError
    from ramp.autonomy.live.foxglove_live import server_tls

    with pytest.raises(LiveViewError, match="needs TLS"):
        FoxgloveLive(host="0.0.0.0")
    with pytest.raises(ValueError, match="go together"):
        server_tls(str(pki / "robot.crt"), None)
    live = FoxgloveLive(host="0.0.0.0", ssl_context=server_tls(str(pki / "robot.crt"),
                                                               str(pki / "robot.key")))
    port = live.start(0.0)
    try:
        assert live.url.startswith("wss://")
        ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
        ctx.load_verify_locations(pki / "ca.crt")
        with connect(f"wss://127.0.0.1:{port}", ssl=ctx,
                     subprotocols=["foxglove.websocket.v1"]) as ws:  # type: ignore[list-item]
            assert "serverInfo" in str(ws.recv(timeout=5))
    finally:
        live.close()
