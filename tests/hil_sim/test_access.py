"""Who may command the robot (SPEC 13), attacked through real TLS handshakes: a stranger on
the network, each role, and a slot flood. The supervisor runs in this thread on a virtual
clock; clients shake hands without blocking while the test turns its loop."""

from __future__ import annotations

import socket
import ssl
from pathlib import Path

import pytest

from tests.harness import MARTE_YAML, Harness, SimHarness
from tests.harness import TestClient as PlainClient
from tests.tls_certs import (
    client_context,
    expired_client,
    forged_client,
    robot_pki,
    serial_of,
    tls_handshake,
)

IDENTITIES = {"ana": "operator", "mon": "observer", "tr": "admin", "bea": "operator"}


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return robot_pki(tmp_path_factory.mktemp("pki"), IDENTITIES)


def access_yaml(pki: Path, local: str = "operator", revoked: tuple[int, ...] = (),
                max_clients: int = 4, per_identity: int = 2, per_address: int = 4) -> str:
    ids = ", ".join(f"{k}: {v}" for k, v in IDENTITIES.items())
    return f"""
server:
  host: 0.0.0.0
  port: 0
  max_clients: {max_clients}
  tls: {{cert: {pki}/robot.crt, key: {pki}/robot.key, client_ca: {pki}/ca.crt}}
access:
  local: {local}
  identities: {{{ids}}}
  revoked: [{", ".join(str(r) for r in revoked)}]
  max_per_identity: {per_identity}
  max_per_address: {per_address}
watchdog: {{timeout: 0.5}}
buses:
  io: {{driver: sim}}
  io2: {{driver: sim}}
modules:
  demo: {{motor: {{bus: io}}, lamp: {{bus: io}}}}
  arm: {{type: demo, motor: {{bus: io2}}, lamp: {{bus: io2}}}}
"""


class TlsClient(PlainClient):
    """A client with a certificate (or none), its handshake driven by the test's pumping."""

    def __init__(self, harness: Harness, ctx: ssl.SSLContext) -> None:
        self.h = harness
        host, port = harness.sup.server.address
        raw = socket.create_connection(("127.0.0.1", port))
        self.buf = b""
        self.closed = False
        self.sock = tls_handshake(raw, ctx, harness.pump_io)
        harness.clients.append(self)
        for _ in range(50):
            harness.pump_io()

    def line(self, max_polls: int = 2000) -> str:
        for _ in range(max_polls):
            if b"\n" in self.buf:
                line, self.buf = self.buf.split(b"\n", 1)
                return line.decode()
            self.h.pump_io()
            try:
                chunk = self.sock.recv(65536)
            except (ssl.SSLWantReadError, BlockingIOError):
                continue
            if not chunk:
                self.closed = True
                raise ConnectionError("server closed the connection")
            self.buf += chunk
        raise TimeoutError("no response line")

    def send(self, data: bytes | str) -> None:
        payload = data.encode() if isinstance(data, str) else data
        while payload:
            try:
                n = self.sock.send(payload)
            except (ssl.SSLWantWriteError, ssl.SSLWantReadError, BlockingIOError):
                self.h.pump_io()
                continue
            payload = payload[n:]


def as_(h: Harness, pki: Path, name: str) -> TlsClient:
    return TlsClient(h, client_context(pki / "ca.crt", pki / f"{name}.crt", pki / f"{name}.key"))


def refused(h: Harness, ctx: ssl.SSLContext) -> str:
    """Connect with `ctx`: the handshake fails, or the server says why and closes. Returns
    what the client saw."""
    try:
        c = TlsClient(h, ctx)
    except (ssl.SSLError, OSError) as exc:
        return f"handshake: {exc}"
    try:
        line = c.line()
    except ConnectionError:
        return "closed"
    except ssl.SSLError as exc:  # TLS 1.3: the client learns of a rejected cert on reading
        return f"read: {exc}"
    with pytest.raises((ConnectionError, ssl.SSLError)):
        c.line()
    return line


@pytest.fixture
def h(pki: Path) -> Harness:
    harness = Harness(access_yaml(pki))
    yield harness
    harness.close()


def test_each_identity_gets_its_role_and_the_robot_names_it(h: Harness, pki: Path) -> None:
    for name, role in IDENTITIES.items():
        c = as_(h, pki, name)
        assert f"robot:access.me=({name},{role})" in c.ask("robot:robot.get=()")
    local = h.connect()
    assert "robot:access.me=(local,operator)" in local.ask("robot:robot.get=()")


def test_an_observer_may_read_and_stop_and_nothing_else(h: Harness, pki: Path) -> None:
    mon = as_(h, pki, "mon")
    changes = ["demo:motor.vel=(40)", "demo:lamp.on=(1)", "robot:watchdog.timeout=(60)",
               "robot:control.acquire=(mon)", "robot:control.release=()"]
    for req in changes:
        answer = mon.ask(req)
        assert "error=(forbidden,observer may not" in answer, (req, answer)
    assert h.world.motors.get("demo.motor", 0.0) == 0.0
    assert "demo:motor.vel=(0)" in mon.ask("demo:demo.get=()")
    ana = as_(h, pki, "ana")
    assert ana.ask("demo:motor.vel=(40)") == ""
    h.advance(0.05)
    assert h.world.motors["demo.motor"] != 0.0
    assert mon.ask("robot:robot.stop=()") == ""  # a stop from every authenticated client
    h.advance(0.05)
    assert h.world.motors["demo.motor"] == 0.0
    assert mon.ask("demo:demo.stop=()") == ""


def test_an_observer_is_refused_every_state_changing_request_the_robot_describes(
        pki: Path) -> None:
    """Every function MARTE describes (and the simulator's `sim` module) that is not a read
    or a stop answers `forbidden` to an observer and changes nothing."""
    secure = access_yaml(pki).split("watchdog:")[0]
    text = "\n".join(secure if line.startswith("server: {host: 127.0.0.1") else line
                     for line in MARTE_YAML.splitlines())
    h = SimHarness(text)
    try:
        mon = as_(h, pki, "mon")
        tr = as_(h, pki, "tr")
        requests = []
        for module in ("robot", "base", "ble", "sim"):
            describe = tr.ask(f"{module}:{module}.describe=()" if module != "robot"
                              else "robot:robot.describe=()")
            kinds = dict(_kinds(describe))
            for (device, fn), params in _functions(describe):
                kind = kinds.get((device, fn), "read")
                if kind in ("read", "stop"):
                    continue
                requests.append((f"{module}:{device}.{fn}=({_sample(params)})", module))
        assert len(requests) > 10
        before = tr.ask("base:base.get=()ble:ble.get=()")
        for req, module in requests:
            answer = mon.ask(req)
            assert "error=(forbidden," in answer, (req, answer)
            if module == "sim":
                assert "sim:" in answer and "admin" in answer
        assert tr.ask("base:base.get=()ble:ble.get=()") == before
        ana = as_(h, pki, "ana")
        assert "forbidden,operator may not" in ana.ask("sim:lift.jam=(1)")
        assert tr.ask("sim:lift.jam=(0)") == ""
    finally:
        h.close()


def _kinds(describe: str) -> list[tuple[tuple[str, str], str]]:
    import re

    return [((d, f), k) for d, f, k in re.findall(r"\w+:(\w+)\.kind=\((\w+),(\w+)\)", describe)]


def _functions(describe: str) -> list[tuple[tuple[str, str], list[str]]]:
    import re

    out = []
    for device, body in re.findall(r"\w+:(\w+)\.function=\(([^)]*)\)", describe):
        name, *params = body.split(",")
        out.append(((device, name), params))
    return out


def _sample(params: list[str]) -> str:
    """A valid value for each described parameter (`int -100..100`, `float`, `name`)."""
    values = []
    for p in params:
        if p.startswith("int"):
            values.append("1" if "0..1" not in p else "0")
        elif p.startswith("float"):
            values.append("0.5")
        else:
            values.append("base")
    return ",".join(values)


def test_strangers_never_reach_the_parser(h: Harness, pki: Path) -> None:
    server = h.sup.server
    ca = pki / "ca.crt"
    other = pki.parent / "other"
    attempts = {
        "no certificate": client_context(ca),
        "another CA's": client_context(ca, other / "ana.crt", other / "ana.key"),
        "expired": client_context(ca, *expired_client(pki, "ana")),
        "forged (own key, same CN)": client_context(ca, *forged_client(pki, "ana")),
    }
    for what, ctx in attempts.items():
        failed = server.handshakes_failed
        seen = refused(h, ctx)
        assert "robot:" not in seen or "forbidden" in seen, (what, seen)
        h.advance(0.1)
        assert not server.clients, what
        assert server.handshakes_failed > failed, what
    assert server.accepted == 0


def test_a_revoked_certificate_is_refused(pki: Path) -> None:
    h = Harness(access_yaml(pki, revoked=(serial_of(pki / "bea.crt"),)))
    try:
        seen = refused(h, client_context(pki / "ca.crt", pki / "bea.crt", pki / "bea.key"))
        assert "forbidden" in seen and "revoked" in seen or "closed" in seen, seen
        assert not h.sup.server.clients
        assert as_(h, pki, "ana").ask("robot:robot.modules=()") == \
            "robot:robot.modules=(demo,arm)"
    finally:
        h.close()


def test_plaintext_on_the_tls_port(pki: Path) -> None:
    """Loopback may speak plain MCP with `access.local`'s role; with `local: none` it is told
    to use TLS and closed before the parser."""
    h = Harness(access_yaml(pki, local="none"))
    try:
        c = h.connect()
        c.send("demo:motor.vel=(50)\n")
        assert "forbidden,this port speaks TLS" in c.line()
        with pytest.raises(ConnectionError):
            c.line()
        assert not h.sup.server.clients
        assert h.world.motors.get("demo.motor", 0.0) == 0.0
    finally:
        h.close()


def test_control_belongs_to_an_identity(h: Harness, pki: Path) -> None:
    ana = as_(h, pki, "ana")
    assert "robot:control.error=(forbidden," in ana.ask("robot:control.acquire=(console)")
    assert "control.owner=(none)" in ana.ask("robot:robot.get=()")
    assert ana.ask("robot:control.acquire=(ana)") == ""
    bea = as_(h, pki, "bea")
    assert "control.owner=(ana)" in bea.ask("robot:robot.get=()")
    assert "not_owner" in bea.ask("demo:motor.vel=(10)")


def test_half_open_and_trickled_handshakes_hold_no_slot_and_expire(pki: Path) -> None:
    """Strangers (loopback stands in for the network: `local: none`) opening connections
    that never finish a handshake hold no slot and are gone after 2 s."""
    h = Harness(access_yaml(pki, local="none"))
    server = h.sup.server
    port = server.address[1]
    half_open = []
    for _ in range(200):  # the loop runs in this thread: let it accept as they come
        half_open.append(socket.create_connection(("127.0.0.1", port)))
        h.pump_io()
    trickle = socket.create_connection(("127.0.0.1", port))
    trickle.send(b"\x16")  # a ClientHello's first byte, then one a second
    for _ in range(300):
        h.pump_io()
    assert len(server.pending) <= 16
    assert not server.clients
    ana = as_(h, pki, "ana")  # an honest handshake still gets through
    assert ana.ask("demo:motor.vel=(30)") == ""
    for _ in range(3):
        trickle.send(b"\x03")
        h.advance(1.0)
        assert ana.ask("") == ""
    assert not server.pending, "every handshake past its 2 s deadline is closed"
    assert [c.identity for c in server.clients.values()] == ["ana"]
    for s in [*half_open, trickle]:
        s.close()
    h.close()


def test_a_silent_local_client_waits_and_then_speaks_plain(h: Harness) -> None:
    """On a TLS port a loopback client may speak plain MCP when it likes (`nc`, a shell
    waiting for its user): no handshake deadline while it is silent."""
    c = h.connect()
    h.advance(5.0)
    assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(demo,arm)"


def test_a_slot_flood_never_keeps_an_operator_from_stopping_the_robot(pki: Path) -> None:
    """The issue's flood: every slot held by clients that keep talking, one of them driving
    with a 60 s timeout. An authenticated operator still connects and stops the wheels."""
    h = Harness(access_yaml(pki, max_clients=8))
    try:
        flood = [h.connect() for _ in range(6)]  # plain loopback clients: unauthenticated
        flood += [as_(h, pki, "mon") for _ in range(2)]  # an observer, at its identity's cap
        driver = flood[0]
        assert driver.ask("robot:watchdog.timeout=(60)") == ""
        assert driver.ask("demo:motor.vel=(40)") == ""
        for _ in range(10):
            h.advance(0.2)
            for c in flood:
                assert c.ask("") == ""
        assert h.world.motors["demo.motor"] != 0.0
        assert len(h.sup.server.clients) == 8
        ana = as_(h, pki, "ana")
        assert ana.ask("robot:robot.stop=()") == ""
        h.advance(0.02)
        assert h.world.motors["demo.motor"] == 0.0
    finally:
        h.close()


def test_one_identity_cannot_hold_every_slot(pki: Path) -> None:
    h = Harness(access_yaml(pki, max_clients=8, per_identity=2))
    try:
        mons = [as_(h, pki, "mon") for _ in range(5)]
        held = [c for c in h.sup.server.clients.values() if c.identity == "mon"]
        assert len(held) == 2  # each newcomer replaced its own identity's longest silent
        assert mons[-1].ask("robot:robot.modules=()").startswith("robot:robot.modules=")
    finally:
        h.close()


def test_serving_off_loopback_without_tls_is_a_config_error(tmp_path: Path) -> None:
    from ramp.config import check_config

    f = tmp_path / "open.yaml"
    f.write_text(MARTE_YAML.replace("server: {host: 127.0.0.1", "server: {host: 0.0.0.0"))
    _, errors = check_config(f)
    assert len(errors) == 1 and errors[0].key == "server.host"
    assert "server.tls" in str(errors[0]) and "allow_anonymous" in str(errors[0])
    f.write_text(f.read_text() + "\naccess: {allow_anonymous: true}\n")
    config, errors = check_config(f)
    assert errors == [] and config is not None


def test_anonymous_mode_is_loud(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    import logging

    from tests.harness import DEMO_YAML

    with caplog.at_level(logging.WARNING, logger="ramp.access"):
        h = Harness(DEMO_YAML + "\naccess: {allow_anonymous: true}\n", host="0.0.0.0")
    try:
        assert "NO authentication" in caplog.text
        c = h.connect()
        answer = c.ask("robot:robot.get=()")
        assert "robot:access.mode=(anonymous)" in answer
        assert "robot:access.me=(local,admin)" in answer
    finally:
        h.close()


def test_who_drove_is_audited_per_identity(pki: Path) -> None:
    """Every state-changing request, accepted or refused, reaches the recorder's audit with
    its sender's identity and address; `ramp log summary` counts them per identity."""
    from ramp.recorder.schemas import TOPIC_EVENTS
    from ramp.recorder.summary import Summary, format_report
    from ramp.runtime.observers import Observer

    seen: list[tuple[str, str, str, str]] = []

    class Audit(Observer):
        def audit(self, t, client, request, outcome):  # type: ignore[no-untyped-def]
            from ramp.mcp.protocol import format_request
            seen.append((client.identity, client.peer, outcome, format_request(request)))

    h = Harness(access_yaml(pki), observer=Audit())
    try:
        ana, mon = as_(h, pki, "ana"), as_(h, pki, "mon")
        assert ana.ask("demo:motor.vel=(20)robot:control.acquire=(ana)") == ""
        mon.ask("demo:lamp.on=(1)")
        bea = as_(h, pki, "bea")
        bea.ask("demo:motor.vel=(5)")  # not_owner
        assert bea.ask("robot:robot.stop=()") == ""
        assert mon.ask("robot:robot.get=()")  # a read: not audited
    finally:
        h.close()
    outcomes = [(who, outcome, req) for who, _, outcome, req in seen]
    assert outcomes == [("ana", "accepted", "demo:motor.vel=(20)"),
                        ("ana", "accepted", "robot:control.acquire=(ana)"),
                        ("mon", "forbidden", "demo:lamp.on=(1)"),
                        ("bea", "not_owner", "demo:motor.vel=(5)"),
                        ("bea", "accepted", "robot:robot.stop=()")]
    assert all(peer.startswith("127.0.0.1:") for _, peer, _, _ in seen)
    summary = Summary()
    for i, (who, peer, outcome, req) in enumerate(seen):
        summary.add((TOPIC_EVENTS, i, {"kind": "audit", "text": f"{who} {peer} {outcome} {req}"}))
    report = summary.report()
    assert report["identities"]["ana"]["commands"] == 1
    assert report["identities"]["ana"]["acquires"] == 1
    assert report["identities"]["mon"]["refusals"] == 1
    assert report["identities"]["bea"] == {"commands": 1, "acquires": 0, "takeovers": 0,
                                           "resets": 0, "refusals": 1,
                                           "addresses": ["127.0.0.1"]}
    assert "identity   mon from 127.0.0.1: 0 commands" in format_report(report)


def test_a_reload_revokes_at_once_and_keeps_everyone_else(h: Harness, pki: Path) -> None:
    """SIGHUP's reload (SPEC 13): a newly revoked client is dropped at once (its motion
    stops with it, as any lost commander's), the others stay, with their new roles."""
    from dataclasses import replace

    ana, bea = as_(h, pki, "ana"), as_(h, pki, "bea")
    assert bea.ask("robot:watchdog.timeout=(60)demo:motor.vel=(30)") == ""
    h.advance(0.05)
    assert h.world.motors["demo.motor"] != 0.0
    access = h.config.access
    identities = {**access.identities, "ana": "observer"}
    dropped = h.sup.server.reload_access(
        replace(access, identities=identities, revoked=frozenset({serial_of(pki / "bea.crt")})),
        None)
    assert len(dropped) == 1
    assert "forbidden,its certificate is revoked" in bea.line()
    h.advance(0.05)
    assert h.world.motors["demo.motor"] == 0.0  # its commander is gone: the watchdog tripped
    assert "robot:access.me=(ana,observer)" in ana.ask("robot:robot.get=()")
    assert "forbidden" in ana.ask("demo:motor.vel=(10)")


def test_sighup_reloads_access_in_a_running_robot(pki: Path, tmp_path: Path) -> None:
    import signal
    import time

    from tests.harness import ask_line, start_ramp, stop_process

    config = tmp_path / "robot.yaml"
    config.write_text(access_yaml(pki))
    proc, host, port = start_ramp(["--sim", "--config", str(config)])
    try:
        ctx = client_context(pki / "ca.crt", pki / "ana.crt", pki / "ana.key")
        with ctx.wrap_socket(socket.create_connection(("127.0.0.1", port)),
                             server_hostname="127.0.0.1") as ana:
            assert "access.me=(ana,operator)" in ask_line(ana, "robot:robot.get=()")
            config.write_text(config.read_text().replace("ana: operator", "ana: observer"))
            proc.send_signal(signal.SIGHUP)
            for _ in range(100):
                if "access.me=(ana,observer)" in ask_line(ana, "robot:robot.get=()"):
                    break
                time.sleep(0.05)
            assert "access.me=(ana,observer)" in ask_line(ana, "robot:robot.get=()")
            assert proc.poll() is None
        proc.terminate()
        _, err = proc.communicate(timeout=10)
        assert "SIGHUP: access reloaded" in err
    finally:
        if proc.poll() is None:
            stop_process(proc)
