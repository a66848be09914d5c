"""`FoxgloveLive`: the autonomy's channels streamed to Foxglove as they are published.

It has the flight recorder's publishing shape (`ramp.recorder.Recorder`): `add_channel(spec)`
with a `ChannelSpec` (topic, schema name, JSON Schema), `publish(t, topic, payload)` with
the clock's seconds and a JSON-able mapping, `start(now)`, `close()`, `timebase.ns(t)`. So
the code that fills a recording can feed a live view, or both at once (`ramp.autonomy.live.tee`).

Never in the tick's way:

- No subscriber on a topic: `publish` is a dictionary look-up and returns (no encoding).
- Otherwise it encodes the payload once (JSON) and appends it to a bounded inbox; when the
  inbox is full (the server thread is starved) the message is dropped and counted.
- The server runs on its own thread with its own asyncio loop. It fans each message out to
  the clients subscribed to its channel. Each client has its own queue with at most `depth`
  messages per channel: a client that reads slowly (a weak Wi-Fi link, a laptop that went to
  sleep) loses its oldest messages of that channel, counted in `dropped`, and always gets the
  latest ones; it never slows the tick or the other clients.
- Clients connect and disconnect at any time; a client that vanishes without closing is
  found by the WebSocket pings (20 s) and forgotten.

Messages carry the time `timebase.ns(t)`: the clock's seconds mapped once to nanoseconds
since the Unix epoch, as the recorder maps them, so Foxglove shows real dates.

Channels named in `latched` (a map sent only when it changes, the mission's state) keep
their last message, and a client that subscribes later gets it at once.

Hostile clients (issue 22's black-box findings):

- **Origin.** A web page open in the operator's browser could otherwise open this socket and
  read the live pose and scans. As the console does, a connection with no `Origin` (a
  desktop app, `ramp-teleop`, a script) or a local one (`http(s)://localhost`,
  `127.0.0.1`, `[::1]`, any port) is served; any other Origin only when it is in `origins`
  (e.g. `https://app.foxglove.dev`); the rest get 403 and a log line.
- **Bounded everything.** A client's message is at most `MAX_CLIENT_MESSAGE` bytes (a
  subscribe of 20,000 channels is closed with 1009, not parsed), one request earns at most
  one status reply, and the status replies waiting for a client that does not read are at
  most `STATUS_DEPTH`, the rest dropped and counted. Frames dropped for newer ones leave no
  trace in the client's queue. One client asking for 20,000 unknown channels over and over
  and never reading grew the process to ~1 GB and stalled the mission's tick for 26 s; now
  its queues stay a few kB and the tick never waits for it.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import ssl
import threading
import time
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from ramp.autonomy.live import protocol
from ramp.common.access import is_loopback
from ramp.common.hostport import format_hostport
from ramp.errors import RampError
from ramp.recorder.jsonbytes import json_payload

if TYPE_CHECKING:
    from websockets.asyncio.server import ServerConnection

log = logging.getLogger("ramp.autonomy.live")

DEFAULT_HOST = "127.0.0.1"
#: Messages kept per channel for each client that has not taken them yet.
DEFAULT_DEPTH = 8
START_TIMEOUT_S = 5.0
#: Largest message a client may send (a subscribe of ~2,000 channels fits).
MAX_CLIENT_MESSAGE = 64 * 1024
#: Status replies kept for a client that has not read them; older ones are dropped, counted.
STATUS_DEPTH = 16
_LOCAL_HOSTS = frozenset({"localhost", "127.0.0.1", "[::1]", "::1"})


def local_origin(origin: str) -> bool:
    """`http(s)://` a name of this machine, any port."""
    scheme, sep, rest = origin.partition("://")
    if not sep or scheme not in ("http", "https"):
        return False
    host = rest.split("/", 1)[0]
    if host.startswith("["):
        host = host[:host.find("]") + 1] if "]" in host else host
    else:
        host = host.rsplit(":", 1)[0] if host.count(":") == 1 else host
    return host.lower() in _LOCAL_HOSTS



class LiveViewError(RampError):
    """The live view cannot serve (the port is taken, the `websockets` library is missing)."""


class ChannelLike(Protocol):
    """What a channel declaration offers (`ramp.recorder.schemas.ChannelSpec` does)."""

    @property
    def topic(self) -> str: ...

    @property
    def schema_name(self) -> str: ...

    @property
    def schema(self) -> Mapping[str, Any]: ...


class Stamps(Protocol):
    """Clock seconds to ns since the Unix epoch (`ramp.recorder.writer.TimeBase` is one)."""

    def ns(self, t: float) -> int: ...


class WallTimeBase:
    """`ns(t) = origin_ns + round((t - t0) * 1e9)`: the clock's time as a real date, running
    exactly as the clock runs (read the wall clock once, at `start`)."""

    def __init__(self, t0: float, origin_ns: int) -> None:
        self.t0 = t0
        self.origin_ns = origin_ns

    def ns(self, t: float) -> int:
        return max(0, self.origin_ns + round((t - self.t0) * 1e9))


@dataclass(frozen=True)
class ClientStats:
    """One connection: `name` (host:port), Message Data frames `sent` to it, `dropped` for
    newer ones while it read slowly, `queued` for it now (at most `depth` a channel), and
    status replies queued and dropped (at most `STATUS_DEPTH` wait)."""

    name: str
    sent: int
    dropped: int
    queued: int
    statuses_queued: int = 0
    statuses_dropped: int = 0


@dataclass(eq=False)
class _Channel:
    id: int
    topic: str
    schema_name: str
    schema: Mapping[str, Any]
    latched: bool
    #: Clients subscribed, with their subscription id (written only by the server thread;
    #: `publish` reads whether it is empty).
    clients: dict[_Client, int] = field(default_factory=dict)
    last: tuple[int, bytes] | None = None

    def advert(self) -> dict[str, Any]:
        return protocol.channel_advert(self.id, self.topic, self.schema_name, self.schema)


@dataclass(eq=False)
class _Client:
    """One connection's state, touched only by the server thread."""

    ws: ServerConnection
    name: str
    wake: asyncio.Event
    subs: dict[int, _Channel] = field(default_factory=dict)          # subscription id ->
    advertised: set[int] = field(default_factory=set)                # channel ids
    control: deque[str] = field(default_factory=deque)               # never dropped
    #: Status replies, at most STATUS_DEPTH; the oldest go first, counted.
    statuses: deque[str] = field(default_factory=deque)
    statuses_dropped: int = 0
    #: Frames in the order they came, as [channel id, frame]; a dropped one's frame is None.
    frames: deque[list[Any]] = field(default_factory=deque)
    per_channel: dict[int, deque[list[Any]]] = field(default_factory=dict)
    sent: int = 0
    dropped: int = 0

    def push(self, channel_id: int, frame: bytes, depth: int) -> int:
        """Queue a frame; returns how many older frames of the channel were dropped."""
        entry = [channel_id, frame]
        queue = self.per_channel.get(channel_id)
        if queue is None:
            queue = self.per_channel[channel_id] = deque()
        queue.append(entry)
        self.frames.append(entry)
        dropped = 0
        while len(queue) > depth:
            queue.popleft()[1] = None
            dropped += 1
        self.dropped += dropped
        if dropped and len(self.frames) > 2 * depth * len(self.per_channel) + 64:
            # A client that never reads: forget the dropped frames' places in the order,
            # or they pile up (None each) for as long as it stays connected.
            self.frames = deque(e for e in self.frames if e[1] is not None)
        self.wake.set()
        return dropped

    def forget(self, channel_id: int) -> None:
        """Drop what is queued on a channel (unsubscribed: nothing more of it is sent)."""
        for entry in self.per_channel.pop(channel_id, ()):
            entry[1] = None

    def say(self, text: str) -> None:
        self.control.append(text)
        self.wake.set()

    def status(self, level: int, message: str) -> None:
        """A status reply; a client that does not read them keeps only the newest."""
        if len(self.statuses) >= STATUS_DEPTH:
            self.statuses.popleft()
            self.statuses_dropped += 1
        self.statuses.append(protocol.status(level, message))
        self.wake.set()

    def advertise(self, channels: Iterable[_Channel]) -> None:
        """Tell the client about the channels it has not heard of yet."""
        new = [ch for ch in channels if ch.id not in self.advertised]
        if new:
            self.advertised.update(ch.id for ch in new)
            self.say(protocol.advertise(ch.advert() for ch in new))


class FoxgloveLive:
    """A Foxglove WebSocket server fed like the flight recorder; see the module docstring.

    `host`/`port`: where to listen (`port=0` picks a free port; `start` returns it).
    `name`: shown by Foxglove. `origin_ns`: the wall clock at `start` (default: read then).
    `latched`: topics whose last message a new subscriber gets at once. `depth`: messages
    kept per channel for a client that reads slowly. `inbox`/`inbox_bytes`: what may wait for
    the server thread before messages are dropped.
    """

    def __init__(self, *, host: str = DEFAULT_HOST, port: int = 0, name: str = "ramp",
                 origin_ns: int | None = None, latched: Iterable[str] = (),
                 depth: int = DEFAULT_DEPTH, inbox: int = 1024,
                 inbox_bytes: int = 8 << 20, origins: Iterable[str] = (),
                 ssl_context: ssl.SSLContext | None = None) -> None:
        if depth < 1:
            raise ValueError("depth must be at least 1")
        if ssl_context is None and not is_loopback(host):
            # SPEC 13: off loopback the view is served only over TLS (wss://), read-only.
            raise LiveViewError(f"foxglove: serving the live view on {host} needs TLS "
                                "(--foxglove-cert and --foxglove-key: a server certificate, "
                                "e.g. the robot's from `ramp certs init`), or 127.0.0.1")
        self.ssl_context = ssl_context
        self.host = host
        self.port = port
        self.name = name
        self.depth = depth
        self.inbox_limit = inbox
        self.inbox_bytes = inbox_bytes
        #: Origins served besides none and local ones (a web app's, e.g. Foxglove's).
        self.origins = frozenset(o.rstrip("/") for o in origins)
        self.refused_origins = 0
        self._origin_ns = origin_ns
        self._latched = frozenset(latched)
        self._channels: dict[str, _Channel] = {}
        self._ids = itertools.count(1)
        self._lock = threading.Lock()  # the channel table and the inbox
        self._inbox: deque[tuple[_Channel, int, bytes]] = deque()
        self._inbox_size = 0
        self._dropped_inbox = 0
        self._dropped_gone = 0  # by clients that have left
        self._sent_gone = 0
        self._bad_topics: set[str] = set()
        self._clients: set[_Client] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._session = ""
        self.timebase: Stamps | None = None

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self, now: float) -> int:
        """Listen; returns the bound port. Raises LiveViewError when it cannot.

        `now`: the clock's time, the origin of the message times (unless `timebase` was set
        before, to share a recorder's)."""
        if self._thread is not None:
            return self.port
        try:
            from websockets.asyncio.server import serve  # noqa: F401 - the optional extra
        except ImportError as exc:
            raise LiveViewError("the Foxglove live view needs the `websockets` library: "
                                "pip install 'ramp[foxglove]'") from exc
        origin = self._origin_ns if self._origin_ns is not None else time.time_ns()
        if self.timebase is None:
            self.timebase = WallTimeBase(now, origin)
        self._session = str(origin)
        # The WebSocket server is an I/O edge: it waits on sockets for clients that come and
        # go at their own pace, so it runs on its own thread and asyncio loop, never on the
        # tick's. The tick only hands it encoded messages through the bounded inbox.
        self._thread = threading.Thread(target=self._run, name="foxglove-live", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT_S):
            raise LiveViewError(f"foxglove: the server did not start within "
                                f"{START_TIMEOUT_S:g} s")
        if self._start_error is not None:
            err, self._start_error = self._start_error, None
            self._thread.join(1.0)
            self._thread = None  # nothing is serving: `start` may be tried again
            self._ready.clear()
            reason = err.strerror if isinstance(err, OSError) and err.strerror else err
            raise LiveViewError(f"foxglove: cannot listen on {self.host}:{self.port}: "
                                f"{reason}") from err
        log.info("foxglove: serving the live view on %s", self.url)
        return self.port

    def close(self, timeout: float = 3.0) -> None:
        """Close every connection and stop the server thread. Idempotent."""
        loop, stop, thread = self._loop, self._stop, self._thread
        if loop is not None and stop is not None:
            with contextlib.suppress(RuntimeError):  # the loop has already ended
                loop.call_soon_threadsafe(stop.set)
        if thread is not None:
            thread.join(timeout)

    def __enter__(self) -> FoxgloveLive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def url(self) -> str:
        """Where Foxglove connects: `ws://HOST:PORT`."""
        scheme = "wss" if self.ssl_context is not None else "ws"
        return f"{scheme}://{format_hostport(self.host, self.port)}"

    # -- figures ------------------------------------------------------------------------------
    @property
    def clients(self) -> int:
        """Connections open now."""
        return len(self._clients)

    @property
    def subscriptions(self) -> int:
        """Subscriptions open now, over every client."""
        return sum(len(ch.clients) for ch in list(self._channels.values()))

    @property
    def dropped(self) -> int:
        """Messages lost: the inbox was full, or a slow client was sent only the latest."""
        return (self._dropped_inbox + self._dropped_gone
                + sum(c.dropped for c in list(self._clients)))

    def client_stats(self) -> list[ClientStats]:
        """Each connection's figures, as of now."""
        return [ClientStats(c.name, c.sent, c.dropped,
                            sum(len(q) for q in list(c.per_channel.values())),
                            len(c.statuses), c.statuses_dropped)
                for c in list(self._clients)]

    @property
    def sent(self) -> int:
        """Message Data frames handed to the clients' connections."""
        return self._sent_gone + sum(c.sent for c in list(self._clients))

    # -- the producer's calls -----------------------------------------------------------------
    def add_channel(self, spec: ChannelLike) -> None:
        """Declare a channel before `publish`ing on it; clients connected now are told."""
        with self._lock:
            known = self._channels.get(spec.topic)
            if known is not None:
                if (known.schema_name, known.schema) != (spec.schema_name, spec.schema):
                    raise ValueError(f"foxglove: topic {spec.topic} is already declared "
                                     "otherwise")
                return
            channel = _Channel(next(self._ids), spec.topic, spec.schema_name,
                               dict(spec.schema), spec.topic in self._latched)
            # A new dict rather than an insertion: `publish` on another thread may be reading.
            self._channels = {**self._channels, spec.topic: channel}
        self._call(self._advertise, channel)

    def wants(self, topic: str) -> bool:
        """Whether a message on `topic` would go anywhere now (a subscriber, or a latched
        channel's last message), so a producer can skip building one nobody watches."""
        channel = self._channels.get(topic)
        return channel is not None and (bool(channel.clients) or channel.latched)

    def publish(self, t: float, topic: str, payload: Mapping[str, Any]) -> None:
        """Stream a payload on a declared channel to its subscribers (cheap; never waits)."""
        channel = self._channels.get(topic)
        if channel is None:
            raise KeyError(f"foxglove: no channel {topic}; declare it with add_channel")
        if not channel.clients and not channel.latched:
            return
        timebase, loop = self.timebase, self._loop
        if timebase is None or loop is None:
            return  # not serving
        try:
            data = json_payload(payload)
        except (TypeError, ValueError) as exc:
            # A payload JSON cannot carry is the producer's bug; it must not stop the tick
            # only because someone is watching. Counted, and said once per topic.
            with self._lock:
                self._dropped_inbox += 1
            if topic not in self._bad_topics:
                self._bad_topics.add(topic)
                log.warning("foxglove: %s: cannot encode the message as JSON (%s); "
                            "dropping such messages", topic, exc)
            return
        with self._lock:
            if (len(self._inbox) >= self.inbox_limit
                    or self._inbox_size + len(data) > self.inbox_bytes):
                self._dropped_inbox += 1
                return
            wake = not self._inbox
            self._inbox.append((channel, timebase.ns(t), data))
            self._inbox_size += len(data)
        if wake:
            with contextlib.suppress(RuntimeError):  # closing: the message goes nowhere
                loop.call_soon_threadsafe(self._fan_out)

    # -- the server thread --------------------------------------------------------------------
    def _call(self, fn: Any, *args: Any) -> None:
        loop = self._loop
        if loop is not None:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(fn, *args)

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        try:
            loop.run_until_complete(self._serve())
        except BaseException as exc:  # noqa: BLE001 - reported by start, never lost
            self._start_error = self._start_error or exc
            log.exception("foxglove: the live view's server stopped")
        finally:
            self._loop = None
            self._ready.set()
            loop.close()

    async def _serve(self) -> None:
        from websockets.asyncio.server import serve
        from websockets.typing import Subprotocol

        self._stop = asyncio.Event()
        try:
            server = await serve(self._connection, self.host, self.port,
                                 subprotocols=[Subprotocol(protocol.SUBPROTOCOL)],
                                 compression=None, max_size=MAX_CLIENT_MESSAGE,
                                 max_queue=4, close_timeout=1.0,
                                 process_request=self._check_origin, ssl=self.ssl_context)
        except OSError as exc:
            self._start_error = exc
            self._ready.set()
            return
        self.port = server.sockets[0].getsockname()[1]
        self._loop = asyncio.get_running_loop()
        self._ready.set()
        try:
            await self._stop.wait()
        finally:
            self._loop = None
            server.close()
            await server.wait_closed()

    def _check_origin(self, ws: ServerConnection, request: Any) -> Any:
        """None (go on) for no Origin, a local one or a configured one; 403 otherwise."""
        origin = request.headers.get("Origin")
        if origin is None or local_origin(origin) or origin.rstrip("/") in self.origins:
            return None
        self.refused_origins += 1
        log.warning("foxglove: refused a connection from origin %s (allowed: none, local, "
                    "or one configured)", origin)
        from http import HTTPStatus
        return ws.respond(HTTPStatus.FORBIDDEN, f"origin {origin} is not allowed\n")

    async def _connection(self, ws: ServerConnection) -> None:
        peer = ws.remote_address
        name = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)
        client = _Client(ws, name, asyncio.Event())
        client.say(protocol.server_info(self.name, self._session))
        client.advertise(list(self._channels.values()))
        self._clients.add(client)
        log.info("foxglove: %s connected", name)
        sender = asyncio.create_task(self._send(client))
        try:
            async for message in ws:
                if isinstance(message, str):
                    self._request(client, message)
                else:
                    client.status(protocol.STATUS_ERROR,
                                  "binary client messages are not supported")
        except Exception as exc:  # noqa: BLE001 - one client's trouble ends that client only
            log.debug("foxglove: %s: %s", name, exc)
        finally:
            self._clients.discard(client)
            for channel in set(client.subs.values()):
                channel.clients.pop(client, None)
            self._dropped_gone += client.dropped
            self._sent_gone += client.sent
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await sender
            log.info("foxglove: %s left (%d messages sent, %d dropped)", name, client.sent,
                     client.dropped)

    def _request(self, client: _Client, text: str) -> None:
        """One client request; at most one status reply, whatever its size."""
        try:
            request = protocol.parse_client_text(text)
        except protocol.ClientRequestError as exc:
            client.status(protocol.STATUS_ERROR, str(exc))
            return
        if isinstance(request, protocol.Subscribe):
            by_id = {ch.id: ch for ch in list(self._channels.values())}
            unknown: list[int] = []
            in_use: list[int] = []
            already: list[str] = []
            for sub_id, channel_id in request.subscriptions:
                channel = by_id.get(channel_id)
                if channel is None:
                    unknown.append(channel_id)
                elif sub_id in client.subs:
                    in_use.append(sub_id)
                elif client in channel.clients:
                    already.append(channel.topic)
                else:
                    client.subs[sub_id] = channel
                    channel.clients[client] = sub_id
                    if channel.last is not None:
                        stamp, data = channel.last
                        client.push(channel.id, protocol.message_data(sub_id, stamp, data),
                                    self.depth)
            problems = []
            if in_use:
                problems.append(f"subscription id {_some(in_use)} is already in use")
            if unknown:
                problems.append(f"no channel {_some(unknown)}")
            if already:
                problems.append(f"already subscribed to {_some(already)}")
            if problems:
                client.status(protocol.STATUS_ERROR if in_use else protocol.STATUS_WARNING,
                              "subscribe: " + "; ".join(problems))
            return
        for sub_id in request.subscription_ids:
            channel = client.subs.pop(sub_id, None)
            if channel is not None:
                channel.clients.pop(client, None)
                client.forget(channel.id)

    def _advertise(self, channel: _Channel) -> None:
        for client in self._clients:
            client.advertise([channel])

    def _fan_out(self) -> None:
        with self._lock:
            batch = list(self._inbox)
            self._inbox.clear()
            self._inbox_size = 0
        for channel, stamp, data in batch:
            if channel.latched:
                channel.last = (stamp, data)
            for client, sub_id in channel.clients.items():
                if client.push(channel.id, protocol.message_data(sub_id, stamp, data),
                               self.depth) and client.dropped == 1:
                    log.warning("foxglove: %s is not keeping up; it gets the latest "
                                "messages and loses older ones (counted)", client.name)

    async def _send(self, client: _Client) -> None:
        """Send a client's queue in order, as fast as its connection takes it."""
        ws = client.ws
        while True:
            while client.control or client.statuses or client.frames:
                if client.control:
                    await ws.send(client.control.popleft())
                    continue
                if client.statuses:
                    await ws.send(client.statuses.popleft())
                    continue
                channel_id, frame = client.frames.popleft()
                if frame is None:
                    continue  # dropped for a newer one, or unsubscribed
                client.per_channel[channel_id].popleft()
                client.sent += 1
                await ws.send(frame)
            client.wake.clear()
            await client.wake.wait()


def _some(items: list[Any]) -> str:
    """The first of a list, and how many more: `7 (and 19999 more)`."""
    more = f" (and {len(items) - 1} more)" if len(items) > 1 else ""
    return f"{items[0]}{more}"


def add_host_arguments(parser: Any) -> None:
    """`--foxglove-host`, `--foxglove-cert`, `--foxglove-key` (SPEC 13): where the live view
    listens, and its server certificate for `wss://` off loopback."""
    parser.add_argument("--foxglove-host", default=DEFAULT_HOST, metavar="HOST",
                        help=f"where the live view listens (default {DEFAULT_HOST}); any "
                             "other address needs --foxglove-cert and --foxglove-key (wss://)")
    parser.add_argument("--foxglove-cert", metavar="FILE",
                        help="the live view's server certificate (e.g. the robot's robot.crt)")
    parser.add_argument("--foxglove-key", metavar="FILE", help="its private key")


def server_tls(cert: str | None, key: str | None) -> ssl.SSLContext | None:
    """The live view's `wss://` context from the flags; ValueError saying what is wrong."""
    if cert is None and key is None:
        return None
    if cert is None or key is None:
        raise ValueError("--foxglove-cert and --foxglove-key go together")
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    try:
        ctx.load_cert_chain(cert, key)
    except (ssl.SSLError, OSError) as exc:
        raise ValueError(f"--foxglove-cert {cert} --foxglove-key {key}: {exc}") from None
    return ctx
