"""McpClient against a tiny scripted TCP server running in a test thread."""

from __future__ import annotations

import socket
import threading
from collections import deque
from collections.abc import Callable, Iterator

import pytest

from ramp.errors import ProtocolError
from ramp.mcp.client import McpClient, errors, parse_address
from ramp.mcp.messages import Request, Response
from ramp.mcp.protocol import LineSplitter, TooLong

Script = Callable[[socket.socket, "Server"], None]


class Server:
    """Accepts one connection and runs `script` on it; records every message it read."""

    def __init__(self, script: Script) -> None:
        self.received: list[bytes] = []
        self.errors: list[BaseException] = []
        self._splitter = LineSplitter()
        self._queue: deque[bytes] = deque()
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(5.0)
        self.port = self._listener.getsockname()[1]
        self.release = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(script,), daemon=True)
        self._thread.start()

    def _run(self, script: Script) -> None:
        try:
            conn, _ = self._listener.accept()
        except OSError as exc:
            self.errors.append(exc)
            return
        with conn:
            conn.settimeout(5.0)
            try:
                script(conn, self)
            except OSError:
                pass  # the client went away first: fine for these scripts
            except BaseException as exc:  # reported to the test in close()
                self.errors.append(exc)

    def read_message(self, conn: socket.socket) -> bytes:
        """Block until the next complete message; record and return it."""
        while not self._queue:
            data = conn.recv(4096)
            if not data:
                raise ConnectionError("client closed")
            for item in self._splitter.feed(data):
                assert not isinstance(item, TooLong)
                self._queue.append(item)
        msg = self._queue.popleft()
        self.received.append(msg)
        return msg

    def close(self) -> None:
        self.release.set()
        self._thread.join(5.0)
        self._listener.close()
        assert not self._thread.is_alive()
        assert not self.errors, self.errors


@pytest.fixture
def serve() -> Iterator[Callable[[Script], Server]]:
    servers: list[Server] = []

    def start(script: Script) -> Server:
        s = Server(script)
        servers.append(s)
        return s

    yield start
    for s in servers:
        s.close()


def answer(replies: dict[bytes, bytes]) -> Script:
    """A server that answers each message it knows, in order, until the client leaves."""

    def script(conn: socket.socket, srv: Server) -> None:
        while True:
            try:
                msg = srv.read_message(conn)
            except ConnectionError:
                return
            conn.sendall(replies[msg])

    return script


def test_request_sends_one_line_and_parses_the_answer(serve: Callable[[Script], Server]) -> None:
    srv = serve(answer({
        b"base:base.get=()": b"base:lf_wheel.vel=(-50)base:battery.volt=(24.5)"
                             b"base:user_led.on=(1)\n",
    }))
    with McpClient(port=srv.port) as c:
        rs = c.request("base:base.get=()")
    assert rs == [
        Response("base", "lf_wheel", "vel", (-50,)),
        Response("base", "battery", "volt", (24.5,)),
        Response("base", "user_led", "on", (1,)),
    ]
    assert srv.received == [b"base:base.get=()"]


def test_send_formats_requests(serve: Callable[[Script], Server]) -> None:
    srv = serve(answer({
        b"base:base.drive=(50,-90)base:user_led.on=(1)": b"\n",
        b"base:base.stop=()": b"\n",
        b"ble:ble.get=()": b"ble:lift.pos=(0.25)\n",
    }))
    with McpClient(port=srv.port) as c:
        drive = [Request("base", "base", "drive", ("50", "-90")),
                 Request("base", "user_led", "on", ("1",))]
        assert c.request(drive) == []
        assert c.request(Request("base", "base", "stop")) == []
        assert c.request(b"ble:ble.get=()\n") == [Response("ble", "lift", "pos", (0.25,))]


def test_heartbeat_is_a_bare_newline(serve: Callable[[Script], Server]) -> None:
    srv = serve(answer({b"": b"\n"}))
    with McpClient(port=srv.port) as c:
        assert c.heartbeat() == []
        assert c.heartbeat() == []
    assert srv.received == [b"", b""]


def test_recv_buffers_coalesced_lines(serve: Callable[[Script], Server]) -> None:
    def script(conn: socket.socket, srv: Server) -> None:
        srv.read_message(conn)
        srv.read_message(conn)
        conn.sendall(b"a:b.c=(1)\na:b.c=(2)\r\n")
        srv.release.wait(5.0)

    srv = serve(script)
    with McpClient(port=srv.port) as c:
        c.send("a:b.c=()")
        c.send("a:b.c=()")
        assert c.recv() == [Response("a", "b", "c", (1,))]
        assert c.has_line()
        assert c.recv() == [Response("a", "b", "c", (2,))]
        assert not c.has_line()


def test_recv_joins_a_fragmented_line(serve: Callable[[Script], Server]) -> None:
    def script(conn: socket.socket, srv: Server) -> None:
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        srv.read_message(conn)
        for b in b"robot:tick.late=(12,40,300)\n":
            conn.sendall(bytes([b]))
        srv.release.wait(5.0)

    srv = serve(script)
    with McpClient(port=srv.port) as c:
        assert c.request("robot:robot.get=()") == [Response("robot", "tick", "late", (12, 40, 300))]


def test_recv_times_out(serve: Callable[[Script], Server]) -> None:
    def script(conn: socket.socket, srv: Server) -> None:
        srv.read_message(conn)
        srv.release.wait(5.0)  # never answers

    srv = serve(script)
    with McpClient(port=srv.port, timeout=0.2) as c:
        c.send("base:base.get=()")
        with pytest.raises(TimeoutError):
            c.recv()
        assert not c.closed


def test_server_close_is_a_connection_error(serve: Callable[[Script], Server]) -> None:
    def script(conn: socket.socket, srv: Server) -> None:
        srv.read_message(conn)

    srv = serve(script)
    c = McpClient(port=srv.port)
    try:
        c.send("base:base.get=()")
        with pytest.raises(ConnectionError):
            c.recv()
        assert c.closed
        with pytest.raises(ConnectionError):
            c.send("base:base.get=()")
        with pytest.raises(ConnectionError):
            c.fileno()
    finally:
        c.close()


def test_garbage_answer_is_a_protocol_error(serve: Callable[[Script], Server]) -> None:
    def script(conn: socket.socket, srv: Server) -> None:
        srv.read_message(conn)
        conn.sendall(b"HTTP/1.1 400 Bad Request\n")
        srv.release.wait(5.0)

    srv = serve(script)
    with McpClient(port=srv.port) as c, pytest.raises(ProtocolError):
        c.request("base:base.get=()")


def test_socket_options_and_lifecycle(serve: Callable[[Script], Server]) -> None:
    srv = serve(lambda conn, s: s.release.wait(5.0) and None)
    c = McpClient(port=srv.port)
    assert c.fileno() >= 0
    sock = c._sock
    assert sock is not None
    assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) != 0
    assert "open" in repr(c)
    c.close()
    c.close()  # idempotent
    assert c.closed and "closed" in repr(c)


def test_send_refuses_embedded_newline(serve: Callable[[Script], Server]) -> None:
    srv = serve(lambda conn, s: s.release.wait(5.0) and None)
    with McpClient(port=srv.port) as c, pytest.raises(ValueError):
        c.send("base:base.get=()\nble:ble.get=()")


def test_connect_refused_is_a_connection_error() -> None:
    probe = socket.create_server(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    with pytest.raises(ConnectionError):
        McpClient(port=port, timeout=1.0)


def test_errors_helper() -> None:
    rs = [
        Response("base", "lf_wheel", "vel", (10,)),
        Response("base", "lf_wheel", "error", ("bad_params", "vel takes one int")),
        Response("robot", "mcp", "error", ("syntax", "x")),
    ]
    assert errors(rs) == rs[1:]
    assert McpClient.errors(rs) == rs[1:]
    assert errors([]) == []


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (None, ("127.0.0.1", 5577)),
        ("", ("127.0.0.1", 5577)),
        ("6000", ("127.0.0.1", 6000)),
        ("robot.local:6000", ("robot.local", 6000)),
        ("robot.local", ("robot.local", 5577)),
        (":6000", ("127.0.0.1", 6000)),
        ("10.0.0.2:", ("10.0.0.2", 5577)),
        ("[::1]:6000", ("::1", 6000)),
        ("[::1]", ("::1", 5577)),
        ("::1", ("::1", 5577)),
    ],
)
def test_parse_address(text: str | None, expected: tuple[str, int]) -> None:
    assert parse_address(text) == expected


def test_parse_address_default_port() -> None:
    assert parse_address(None, default_port=7000) == ("127.0.0.1", 7000)
    assert parse_address("h", default_port=7000) == ("h", 7000)


@pytest.mark.parametrize("bad", ["h:0", "h:65536", "h:x", "[::1", "[::1]x", "[]:5"])
def test_parse_address_rejects(bad: str) -> None:
    with pytest.raises(ValueError):
        parse_address(bad)
