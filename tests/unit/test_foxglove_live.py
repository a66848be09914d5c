"""The Foxglove live view, against a real WebSocket client (the `websockets` library) on
loopback: the handshake, serverInfo and advertise, subscriptions and the Message Data frames
they bring (opcode, subscription id, time, payload), clients that come, go, vanish or read
too slowly, and one producer feeding a recording and the live view at once."""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import struct
import threading
import time
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import InvalidStatus

from ramp.autonomy.live import DEFAULT_HOST, FoxgloveLive, LiveViewError, tee
from ramp.recorder import ChannelSpec, Recorder, RecorderConfig
from ramp.recorder.writer import recording_files

ORIGIN = 1_779_285_600_000_000_000  # 2026-05-20 14:00:00 UTC
T0 = 100.0  # the clock's time at start
WAIT_S = 5.0  # generous: a bound on waiting for the server thread, never a speed claim

POSE = ChannelSpec("/pose/estimated", "foxglove.PoseInFrame", {
    "title": "foxglove.PoseInFrame", "type": "object",
    "properties": {"frame_id": {"type": "string"},
                   "pose": {"type": "object", "title": "foxglove.Pose"}}})
STATE = ChannelSpec("/mission/state", "ramp.MissionState", {
    "title": "ramp.MissionState", "type": "object",
    "properties": {"state": {"type": "string"}}, "required": ["state"]})
BIG = ChannelSpec("/lidar/scan", "foxglove.LaserScan", {
    "title": "foxglove.LaserScan", "type": "object",
    "properties": {"ranges": {"type": "array", "items": {"type": "number"}}}})


@pytest.fixture
def live() -> Iterator[FoxgloveLive]:
    server = FoxgloveLive(origin_ns=ORIGIN, name="ramp-test")
    server.add_channel(POSE)
    server.add_channel(STATE)
    server.start(T0)
    yield server
    server.close()


async def until(cond: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not cond():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        await asyncio.sleep(0.002)


class Client:
    """A Foxglove client as the app is one, with helpers that fail instead of hanging."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self.channels: dict[str, dict[str, Any]] = {}

    async def recv(self) -> str | bytes:
        return await asyncio.wait_for(self.ws.recv(), WAIT_S)

    async def json(self) -> dict[str, Any]:
        msg = await self.recv()
        assert isinstance(msg, str), f"expected a text message, got {msg[:20]!r}"
        out = json.loads(msg)
        assert isinstance(out, dict)
        return out

    async def handshake(self) -> dict[str, Any]:
        """serverInfo, then advertise; returns serverInfo."""
        info = await self.json()
        adv = await self.json()
        assert adv["op"] == "advertise"
        self.channels.update({ch["topic"]: ch for ch in adv["channels"]})
        return info

    async def frame(self) -> tuple[int, int, Any]:
        """(subscription id, timestamp ns, decoded payload) of the next Message Data."""
        msg = await self.recv()
        assert isinstance(msg, bytes), f"expected a binary frame, got {msg!r}"
        opcode, sub, stamp = struct.unpack_from("<BIQ", msg)
        assert opcode == 0x01
        return sub, stamp, json.loads(msg[13:])

    async def subscribe(self, live: FoxgloveLive, **subs: int) -> None:
        """subscribe(live, topic_as_key=sub_id): waits until the server holds them."""
        before = live.subscriptions
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": sub_id, "channelId": self.channels[_topic(key)]["id"]}
            for key, sub_id in subs.items()]}))
        await until(lambda: live.subscriptions == before + len(subs), "the subscription")


def _topic(key: str) -> str:
    return {"pose": POSE.topic, "state": STATE.topic, "scan": BIG.topic}.get(key, key)


@asynccontextmanager
async def client(live: FoxgloveLive, **kw: Any) -> AsyncIterator[Client]:
    async with connect(live.url, subprotocols=["foxglove.websocket.v1"], **kw) as ws:
        c = Client(ws)
        await c.handshake()
        yield c


def stamp(t: float) -> int:
    return ORIGIN + round((t - T0) * 1e9)


# -- handshake --------------------------------------------------------------------------------
def test_a_client_gets_server_info_then_every_channel_with_its_json_schema(
        live: FoxgloveLive) -> None:
    async def run() -> None:
        async with connect(live.url, subprotocols=["foxglove.websocket.v1"]) as ws:
            assert ws.subprotocol == "foxglove.websocket.v1"
            c = Client(ws)
            info = await c.handshake()
            assert info["op"] == "serverInfo" and info["name"] == "ramp-test"
            assert info["capabilities"] == [] and info["sessionId"] == str(ORIGIN)
            assert set(c.channels) == {POSE.topic, STATE.topic}
            for spec in (POSE, STATE):
                ch = c.channels[spec.topic]
                assert ch["encoding"] == "json" and ch["schemaEncoding"] == "jsonschema"
                assert ch["schemaName"] == spec.schema_name
                assert json.loads(ch["schema"]) == spec.schema
            assert len({ch["id"] for ch in c.channels.values()}) == 2

    asyncio.run(run())


def test_a_client_without_the_foxglove_subprotocol_is_refused(live: FoxgloveLive) -> None:
    async def run() -> None:
        with pytest.raises(InvalidStatus) as err:
            async with connect(live.url):
                pass
        assert err.value.response.status_code == 400
        with pytest.raises(InvalidStatus):
            async with connect(live.url, subprotocols=["foxglove.websocket.v2"]):
                pass

    asyncio.run(run())


def test_port_zero_picks_a_free_port_on_localhost_and_a_taken_port_is_an_error(
        live: FoxgloveLive) -> None:
    assert live.host == DEFAULT_HOST == "127.0.0.1"
    assert live.port > 0 and live.url == f"ws://127.0.0.1:{live.port}"
    other = FoxgloveLive(port=live.port)
    with pytest.raises(LiveViewError, match=rf"cannot listen on 127\.0\.0\.1:{live.port}"):
        other.start(0.0)
    other.port = 0  # once the port is put right, it starts
    try:
        assert other.start(0.0) not in (0, live.port)
    finally:
        other.close()


# -- subscriptions ----------------------------------------------------------------------------
def test_a_subscriber_receives_message_data_with_its_id_time_and_payload(
        live: FoxgloveLive) -> None:
    async def run() -> None:
        async with client(live) as c:
            await c.subscribe(live, pose=42)
            live.publish(T0 + 0.5, STATE.topic, {"state": "not subscribed"})
            pose = {"frame_id": "arena", "pose": {"position": {"x": 1.25, "y": -0.5, "z": 0.0},
                                                  "orientation": {"w": 1.0}}}
            live.publish(T0 + 1.25, POSE.topic, pose)
            live.publish(T0 + 1.5, POSE.topic, {"frame_id": "arena", "q": float("nan")})
            assert await c.frame() == (42, stamp(T0 + 1.25), pose)
            assert await c.frame() == (42, stamp(T0 + 1.5), {"frame_id": "arena", "q": None})
            assert live.sent == 2 and live.dropped == 0

    asyncio.run(run())


def test_after_unsubscribe_no_more_messages_of_that_channel_arrive(live: FoxgloveLive) -> None:
    async def run() -> None:
        async with client(live) as c:
            await c.subscribe(live, pose=1, state=2)
            live.publish(T0 + 1, POSE.topic, {"n": 1})
            assert (await c.frame())[::2] == (1, {"n": 1})
            await c.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [1]}))
            await until(lambda: live.subscriptions == 1, "the unsubscription")
            live.publish(T0 + 2, POSE.topic, {"n": 2})
            live.publish(T0 + 3, STATE.topic, {"state": "dock"})
            assert (await c.frame())[::2] == (2, {"state": "dock"})  # not pose's n=2
            await c.subscribe(live, pose=1)  # the id may be used again
            live.publish(T0 + 4, POSE.topic, {"n": 4})
            assert (await c.frame())[::2] == (1, {"n": 4})

    asyncio.run(run())


def test_two_clients_get_the_same_messages_each_with_its_own_subscription_id(
        live: FoxgloveLive) -> None:
    async def run() -> None:
        async with client(live) as a, client(live) as b:
            await a.subscribe(live, state=5)
            await b.subscribe(live, state=9)
            live.publish(T0 + 1, STATE.topic, {"state": "excavate"})
            assert await a.frame() == (5, stamp(T0 + 1), {"state": "excavate"})
            assert await b.frame() == (9, stamp(T0 + 1), {"state": "excavate"})

    asyncio.run(run())


def test_a_channel_declared_later_is_advertised_to_connected_clients(
        live: FoxgloveLive) -> None:
    async def run() -> None:
        async with client(live) as c:
            live.add_channel(BIG)
            live.add_channel(BIG)  # the same declaration again changes nothing
            adv = await c.json()
            assert adv["op"] == "advertise"
            assert [ch["topic"] for ch in adv["channels"]] == [BIG.topic]
            c.channels[BIG.topic] = adv["channels"][0]
            await c.subscribe(live, scan=3)
            live.publish(T0 + 2, BIG.topic, {"ranges": [1.5, 2.0]})
            assert await c.frame() == (3, stamp(T0 + 2), {"ranges": [1.5, 2.0]})

    asyncio.run(run())


def test_bad_or_unsupported_requests_get_a_status_and_change_nothing(
        live: FoxgloveLive) -> None:
    async def run() -> None:
        async with client(live) as c:
            pose_id = c.channels[POSE.topic]["id"]
            sends: list[tuple[str | bytes, int, str]] = [
                ("not json", 2, "not JSON"),
                (json.dumps({"op": "getParameters", "parameterNames": []}), 2, "not supported"),
                (json.dumps({"op": "subscribe", "subscriptions": [
                    {"id": 1, "channelId": 999}]}), 1, "no channel 999"),
                (b"\x01\x00\x00\x00\x00{}", 2, "binary client messages"),
            ]
            for message, level, text in sends:
                await c.ws.send(message)
                status = await c.json()
                assert status["op"] == "status" and status["level"] == level
                assert text in status["message"]
            assert live.subscriptions == 0
            await c.subscribe(live, pose=1)
            await c.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": 1, "channelId": c.channels[STATE.topic]["id"]}]}))
            assert "already in use" in (await c.json())["message"]
            await c.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": 2, "channelId": pose_id}]}))
            assert "already subscribed" in (await c.json())["message"]
            assert live.subscriptions == 1
            live.publish(T0 + 1, POSE.topic, {"still": "works"})
            assert await c.frame() == (1, stamp(T0 + 1), {"still": "works"})

    asyncio.run(run())


def test_a_latched_channel_gives_a_late_subscriber_its_last_message() -> None:
    live = FoxgloveLive(origin_ns=ORIGIN, latched=[STATE.topic])
    live.add_channel(STATE)
    live.add_channel(POSE)

    async def run() -> None:
        live.publish(T0 + 1, STATE.topic, {"state": "scan_for_obstacles"})
        live.publish(T0 + 2, STATE.topic, {"state": "plan_path"})
        live.publish(T0 + 2, POSE.topic, {"frame_id": "not latched"})
        # The messages reach the server thread before the client's connection does.
        async with client(live) as c:
            await c.subscribe(live, state=4, pose=5)
            assert await c.frame() == (4, stamp(T0 + 2), {"state": "plan_path"})
            live.publish(T0 + 3, POSE.topic, {"frame_id": "arena"})
            assert await c.frame() == (5, stamp(T0 + 3), {"frame_id": "arena"})

    try:
        live.start(T0)
        asyncio.run(run())
    finally:
        live.close()


# -- never in the tick's way ------------------------------------------------------------------
def test_without_subscribers_publish_does_not_even_encode(
        live: FoxgloveLive, caplog: pytest.LogCaptureFixture) -> None:
    unencodable = {"frame_id": {1, 2}}  # a set: JSON cannot carry it

    async def run() -> None:
        live.publish(T0, POSE.topic, unencodable)  # nobody connected
        async with client(live) as c:
            live.publish(T0, POSE.topic, unencodable)  # connected, not subscribed
            assert live.dropped == 0 and live.sent == 0
            await c.subscribe(live, pose=1)
            with caplog.at_level(logging.WARNING, "ramp.autonomy.live"):
                live.publish(T0, POSE.topic, unencodable)  # now it is encoded: and refused
                live.publish(T0, POSE.topic, unencodable)
            assert live.dropped == 2
            assert [r.getMessage() for r in caplog.records].count(
                caplog.records[0].getMessage()) == 1
            assert "cannot encode" in caplog.records[0].getMessage()
            live.publish(T0 + 1, POSE.topic, {"frame_id": "arena"})
            assert await c.frame() == (1, stamp(T0 + 1), {"frame_id": "arena"})

    asyncio.run(run())


def test_a_slow_client_loses_old_messages_counted_and_stalls_neither_publish_nor_others(
) -> None:
    live = FoxgloveLive(origin_ns=ORIGIN, depth=4, inbox_bytes=64 << 20)  # no inbox drops
    live.add_channel(BIG)
    blob = "r" * 65_536
    count = 160  # 10 MB: more than loopback's socket buffers can hold for a client that
    #              does not read (tcp_wmem's 4 MB at most on the server's side)

    async def run() -> None:
        # The slow client: a small receive buffer, and it never reads after subscribing.
        sock = socket.create_connection(("127.0.0.1", live.port))
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.setblocking(False)
        async with connect(live.url, sock=sock, max_queue=1,
                           subprotocols=["foxglove.websocket.v1"]) as slow_ws, \
                client(live) as fast:
            slow = Client(slow_ws)
            await slow.handshake()
            await slow.subscribe(live, scan=1)
            await fast.subscribe(live, scan=2)
            longest = 0.0
            for i in range(count):
                t = time.perf_counter()
                live.publish(T0 + i * 0.1, BIG.topic, {"i": i, "blob": blob})
                longest = max(longest, time.perf_counter() - t)
                if i % 16 == 0:
                    await asyncio.sleep(0)  # the fast client reads now and then
            live.publish(T0 + 100, BIG.topic, {"i": "last"})
            while True:  # the fast client gets the latest message, whatever it lost
                sub, when, payload = await fast.frame()
                assert sub == 2
                if payload["i"] == "last":
                    assert when == stamp(T0 + 100)
                    break
            assert longest < 1.0, "publish waited for a client"  # generous: it never waits
            await until(lambda: live.dropped > 0, "drops to be counted")
            assert live.clients == 2  # the slow client is still served, only thinned out
            me = "{}:{}".format(*sock.getsockname()[:2])
            (stuck,) = [s for s in live.client_stats() if s.name == me]
            assert stuck.dropped > 0 and stuck.queued <= 4  # its memory stays bounded
            assert stuck.sent + stuck.dropped + stuck.queued == count + 1  # all accounted
            assert live.dropped >= stuck.dropped
            slow_ws.transport.abort()  # it would not read the closing handshake either

    try:
        live.start(T0)
        asyncio.run(run())
    finally:
        live.close()


def test_a_starved_server_thread_costs_messages_counted_never_a_wait(
        live: FoxgloveLive) -> None:
    live.inbox_limit = 3

    async def run() -> None:
        async with client(live) as c:
            await c.subscribe(live, state=1)
            gate = threading.Event()
            assert live._loop is not None
            live._loop.call_soon_threadsafe(gate.wait, WAIT_S)  # the server thread is stuck
            try:
                for i in range(5):
                    live.publish(T0 + i, STATE.topic, {"state": f"s{i}"})
                assert live.dropped == 2  # the inbox held 3
            finally:
                gate.set()
            for i in range(3):
                assert (await c.frame())[::2] == (1, {"state": f"s{i}"})
            live.publish(T0 + 9, STATE.topic, {"state": "again"})
            assert (await c.frame())[::2] == (1, {"state": "again"})

    asyncio.run(run())


def test_a_client_that_vanishes_is_forgotten_and_publishing_goes_on(
        live: FoxgloveLive) -> None:
    async def run() -> None:
        async with client(live) as stays:
            await stays.subscribe(live, state=1)
            async with client(live) as goes:
                await goes.subscribe(live, state=7, pose=8)
                assert live.clients == 2 and live.subscriptions == 3
                goes.ws.transport.abort()  # the TCP connection is cut: no closing handshake
                await until(lambda: live.clients == 1 and live.subscriptions == 1,
                            "the server to forget the vanished client")
            for i in range(5):
                live.publish(T0 + i, STATE.topic, {"state": f"s{i}"})
                live.publish(T0 + i, POSE.topic, {"nobody": "listens"})
            for i in range(5):
                assert (await stays.frame())[::2] == (1, {"state": f"s{i}"})

    asyncio.run(run())


# -- the recorder's shape ---------------------------------------------------------------------
def test_publishing_an_undeclared_topic_or_redeclaring_one_otherwise_fails(
        live: FoxgloveLive) -> None:
    with pytest.raises(KeyError, match="no channel /nope"):
        live.publish(T0, "/nope", {})
    with pytest.raises(ValueError, match="already declared otherwise"):
        live.add_channel(ChannelSpec(POSE.topic, "other", {}))


def test_close_is_idempotent_and_publish_before_start_or_after_close_is_harmless() -> None:
    live = FoxgloveLive(latched=[STATE.topic])
    live.add_channel(STATE)
    live.publish(0.0, STATE.topic, {"state": "too early"})
    live.close()  # never started
    live.start(0.0)
    live.close()
    live.close()
    live.publish(1.0, STATE.topic, {"state": "too late"})
    assert live.dropped == 0 and live.clients == 0


def test_a_tee_feeds_a_recording_and_the_live_view_the_same_messages_and_times(
        tmp_path: Path) -> None:
    rec = Recorder(RecorderConfig(str(tmp_path / "rec")), origin_ns=ORIGIN)
    live = FoxgloveLive(origin_ns=ORIGIN + 123)  # its own origin would differ: the tee's wins
    sink = tee(rec, None, live)
    assert sink.sinks == [rec, live]
    sink.add_channel(POSE)

    async def run() -> None:
        async with client(live) as c:
            await c.subscribe(live, pose=6)
            sink.publish(T0 + 0.25, POSE.topic, {"frame_id": "arena"})
            assert await c.frame() == (6, stamp(T0 + 0.25), {"frame_id": "arena"})

    try:
        sink.start(T0)
        assert live.timebase is rec.timebase is sink.timebase
        asyncio.run(run())
    finally:
        sink.close()
    ((_, path),) = recording_files(tmp_path / "rec")
    with open(path, "rb") as f:
        got = [(ch.topic, schema.name, m.log_time, json.loads(m.data))
               for schema, ch, m in make_reader(f).iter_messages()]
    assert got == [(POSE.topic, "foxglove.PoseInFrame", stamp(T0 + 0.25),
                    {"frame_id": "arena"})]


def test_a_tee_of_nothing_publishes_nowhere() -> None:
    sink = tee(None)
    sink.add_channel(POSE)
    sink.start(0.0)
    sink.publish(0.0, POSE.topic, {})
    assert sink.timebase is None
    sink.close()


# -- hostile clients (issue 22) ----------------------------------------------------------------
def test_a_page_of_another_site_is_refused_and_local_or_configured_origins_are_served() -> None:
    from ramp.autonomy.live.foxglove_live import local_origin

    assert local_origin("http://127.0.0.1:8080") and local_origin("http://localhost")
    assert local_origin("https://[::1]:3000") and not local_origin("http://evil.example")
    assert not local_origin("null") and not local_origin("http://127.0.0.1.evil.example")
    live = FoxgloveLive(origin_ns=ORIGIN, origins=["https://app.foxglove.dev"])
    live.add_channel(POSE)

    async def run() -> None:
        with pytest.raises(InvalidStatus) as refused:
            async with connect(live.url, subprotocols=["foxglove.websocket.v1"],
                               origin="http://evil.example"):  # type: ignore[arg-type]
                pass
        assert refused.value.response.status_code == 403
        for origin in (None, "http://localhost:8080", "https://app.foxglove.dev"):
            async with client(live, origin=origin) as c:
                assert POSE.topic in c.channels
        assert live.refused_origins == 1

    try:
        live.start(T0)
        asyncio.run(run())
    finally:
        live.close()


def test_a_client_asking_for_thousands_of_unknown_channels_and_never_reading_stays_bounded(
) -> None:
    """The black-box finding: 20,000 unknown channels asked for over and over by a client
    that never reads grew the process to ~1 GB and stalled the tick. One message of 20,000
    is refused whole (too big); 1,500 at a time, 200 times, earn one status each, and only the
    newest STATUS_DEPTH wait; publish on the tick's thread never waits."""
    from websockets.exceptions import ConnectionClosed

    from ramp.autonomy.live.foxglove_live import STATUS_DEPTH

    live = FoxgloveLive(origin_ns=ORIGIN)
    live.add_channel(POSE)
    many = json.dumps({"op": "subscribe", "subscriptions": [
        {"id": i, "channelId": 1_000_000 + i} for i in range(20_000)]})
    some = json.dumps({"op": "subscribe", "subscriptions": [
        {"id": i, "channelId": 1_000_000 + i} for i in range(1_500)]})
    assert len(some) < 64 * 1024 < len(many)

    async def run() -> None:
        async with client(live) as big:
            await big.ws.send(many)
            with pytest.raises(ConnectionClosed):
                while True:
                    await big.recv()
            assert big.ws.close_code == 1009
        sock = socket.create_connection(("127.0.0.1", live.port))
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.setblocking(False)
        async with connect(live.url, sock=sock, max_queue=1,
                           subprotocols=["foxglove.websocket.v1"]) as ws:
            stuck = Client(ws)
            await stuck.handshake()
            longest = 0.0
            asked = 0
            for i in range(200):
                try:  # until the server stops reading it (its replies are not read)
                    await asyncio.wait_for(ws.send(some), 0.5)
                except TimeoutError:
                    break
                asked += 1
                t = time.perf_counter()
                live.publish(T0 + i, POSE.topic, {"i": i})
                longest = max(longest, time.perf_counter() - t)
            assert asked > 2 * STATUS_DEPTH
            me = "{}:{}".format(*sock.getsockname()[:2])
            await asyncio.sleep(0.2)  # let the server thread take every request
            (stats,) = [s for s in live.client_stats() if s.name == me]
            assert stats.statuses_queued <= STATUS_DEPTH
            # Each request got one reply: sent (into the socket buffers), queued or dropped.
            assert stats.statuses_dropped + stats.statuses_queued <= asked
            assert longest < 0.005, f"publish took {longest * 1000:.1f} ms"
            ws.transport.abort()

    try:
        live.start(T0)
        asyncio.run(run())
    finally:
        live.close()


def test_status_replies_waiting_for_a_client_are_bounded_and_counted() -> None:
    from ramp.autonomy.live.foxglove_live import STATUS_DEPTH, _Client

    c = _Client(None, "x", asyncio.Event())  # type: ignore[arg-type]
    for i in range(1000):
        c.status(1, f"reply {i}")
    assert len(c.statuses) == STATUS_DEPTH and c.statuses_dropped == 1000 - STATUS_DEPTH
    assert "reply 999" in c.statuses[-1]
    for _ in range(10_000):  # frames of one channel, never sent: the order list stays small
        c.push(1, b"frame", depth=4)
    assert len(c.frames) < 200 and len(c.per_channel[1]) == 4
