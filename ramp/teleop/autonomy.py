"""The console's second link: the autonomy's live view, as a `foxglove.websocket.v1` client.

`ramp-teleop --autonomy HOST:PORT` connects to the view `ramp-autonomy --foxglove-port` (or
`ramp sim mission --foxglove-port`) serves and keeps what the page draws (SPEC 7.1). The
console must not need it: a view that is absent or unreachable is reported and retried, and
nothing else waits for it.

Only what is drawn, at the rate it is drawn (RMC scored the operator link's bandwidth):
- `/mission/state`, `/map`, `/obstacles` and `/arena` stay subscribed: they are sent only
  when they change, and the server gives their last message at once (latched);
- `/pose/estimated`, `/pose/true` (a simulator's), `/mission/numbers` are published at
  10 Hz; the console takes one of each every `pose_period` (0.5 s): it subscribes, and
  unsubscribes as soon as each has come;
- `/lidar/scan` (6–7 kB each, up to a few a second) the same, every `scan_period` (2 s).
The protocol has no rate setting, so this subscribe-take-one-unsubscribe cycle is how a
client asks for less; it costs ~150 bytes a cycle against ~6 kB/s of pose and numbers at
10 Hz. The module never imports the autonomy (`ramp.autonomy`): the view's messages are read
as the JSON any Foxglove client sees.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger("ramp.teleop")

SUBPROTOCOL = "foxglove.websocket.v1"
STATE, MAP = "/mission/state", "/map"
POSE, TRUE_POSE, NUMBERS, SCAN = "/pose/estimated", "/pose/true", "/mission/numbers", \
    "/lidar/scan"
ARENA, OBSTACLES = "/arena", "/obstacles"
ALWAYS = (STATE, MAP, ARENA, OBSTACLES)
POSE_PERIOD_S = 0.5
SCAN_PERIOD_S = 2.0
RETRY_S = 1.0
#: No message at all for this long while connected: the view is stale.
STALE_AFTER_S = 3.0
#: Points of a scan sent to the page (a 1,081-beam scan is thinned).
SCAN_POINTS = 270
_HEADER = struct.Struct("<BIQ")


@dataclass
class ViewState:
    """What the console knows of the autonomy, as the page draws it."""

    connected: bool = False
    detail: str = "connecting"
    state: str = ""
    previous: str = ""
    trigger: str = ""
    reason: str = ""
    #: Loop time at which the mission entered `state` (from the message's stamp).
    state_since: float | None = None
    #: The mission's localization as it publishes it (`none`, `ok`, `lost`, `relocalizing`).
    localization: str = ""
    numbers: dict[str, Any] = field(default_factory=dict)
    pose: tuple[float, float, float] | None = None
    true_pose: tuple[float, float, float] | None = None
    #: Loop time of the last message on any channel.
    last_message: float | None = None
    scan: list[tuple[float, float]] = field(default_factory=list)
    scan_at: float | None = None
    map: dict[str, Any] = field(default_factory=dict)
    map_version: int = 0
    scan_version: int = 0

    def stale(self, now: float) -> bool:
        return not self.connected or self.last_message is None \
            or now - self.last_message > STALE_AFTER_S

    def summary(self, now: float) -> dict[str, Any]:
        """The small part sent to the page at each update."""
        return {
            "connected": self.connected, "detail": self.detail, "stale": self.stale(now),
            "state": self.state, "previous": self.previous, "trigger": self.trigger,
            "reason": self.reason, "localization": self.localization,
            "in_state_s": None if self.state_since is None else round(now - self.state_since,
                                                                      1),
            "numbers": self.numbers, "pose": self.pose, "true_pose": self.true_pose,
            "map_version": self.map_version, "scan_version": self.scan_version,
        }


def yaw_of(q: dict[str, Any]) -> float:
    """The heading of a quaternion, radians."""
    x, y, z, w = (float(q.get(k, 0.0)) for k in "xyzw")
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def _rotate(q: tuple[float, float, float, float], v: tuple[float, float, float]
            ) -> tuple[float, float, float]:
    x, y, z, w = q
    vx, vy, vz = v
    # v' = v + 2w(q×v) + 2 q×(q×v)
    cx, cy, cz = y * vz - z * vy, z * vx - x * vz, x * vy - y * vx
    cx2, cy2, cz2 = y * cz - z * cy, z * cx - x * cz, x * cy - y * cx
    return vx + 2 * (w * cx + cx2), vy + 2 * (w * cy + cy2), vz + 2 * (w * cz + cz2)


def scan_points(msg: dict[str, Any], limit: int = SCAN_POINTS) -> list[tuple[float, float]]:
    """A `foxglove.LaserScan` placed in the arena: its returns as floor points (x, y), cm."""
    ranges = msg.get("ranges") or []
    n = len(ranges)
    if n < 2:
        return []
    pose = msg.get("pose") or {}
    pos, ori = pose.get("position") or {}, pose.get("orientation") or {}
    q = tuple(float(ori.get(k, 0.0)) for k in "xyzw")
    px, py = float(pos.get("x", 0.0)), float(pos.get("y", 0.0))
    start, end = float(msg.get("start_angle", 0.0)), float(msg.get("end_angle", 0.0))
    step = max(1, math.ceil(n / limit))
    out = []
    for i in range(0, n, step):
        r = ranges[i]
        if not isinstance(r, int | float) or not r > 0 or not math.isfinite(r):
            continue
        a = start + (end - start) * i / (n - 1)
        dx, dy, _ = _rotate(q, (r * math.cos(a), r * math.sin(a), 0.0))  # type: ignore[arg-type]
        out.append((round(px + dx, 2), round(py + dy, 2)))
    return out


def _points(line: dict[str, Any]) -> list[tuple[float, float]]:
    return [(round(float(p.get("x", 0.0)), 3), round(float(p.get("y", 0.0)), 3))
            for p in line.get("points") or []]


def map_view(scene: dict[str, Any], previous: dict[str, Any] | None = None) -> dict[str, Any]:
    """A `foxglove.SceneUpdate` of the autonomy's map, as the page draws it: walls, regions,
    collector, the plan's legs. The obstacles (`/obstacles`) and the arena's size (`/arena`)
    come on their own typed channels and are kept from `previous`."""
    out: dict[str, Any] = {"walls": [], "regions": [], "collector": [], "plan": [],
                           "obstacles": [], "arena": None, "robot": [1.2, 0.75]}
    for key in ("obstacles", "arena", "robot"):
        if previous and previous.get(key) is not None:
            out[key] = previous[key]
    for entity in scene.get("entities") or []:
        lines = entity.get("lines") or []
        meta = {m.get("key"): m.get("value") for m in entity.get("metadata") or []
                if isinstance(m, dict)}
        if entity.get("id") == "arena":
            names = str(meta.get("lines", "")).split(",")
            for name, line in zip(names, lines, strict=False):
                (out["collector"] if name == "collector" else out["regions"]).append(
                    _points(line))
            with contextlib.suppress(KeyError, TypeError, ValueError):
                out["robot"] = [float(str(meta["robot_length"])),
                                float(str(meta["robot_width"]))]
            continue
        if lines:
            out["walls"] = _points(lines[0])
            out["plan"] = [_points(line) for line in lines[1:]]
    size = out["arena"]
    if size is not None:  # `/arena` says it as typed fields: it wins over metadata text
        out["robot"] = [size["robot_length_m"], size["robot_width_m"]]
    return out


def obstacles_view(msg: dict[str, Any]) -> list[dict[str, Any]]:
    """`ramp.Obstacles` as the page draws it: kind, x, y, radius (unknown kinds kept: the
    page draws them as obstacles of no known kind)."""
    out = []
    for o in msg.get("obstacles") or []:
        with contextlib.suppress(TypeError, ValueError, AttributeError):
            out.append({"kind": str(o.get("kind", "")), "x": round(float(o["x"]), 3),
                        "y": round(float(o["y"]), 3), "radius": round(float(o["radius"]), 3)})
    return out


def arena_view(msg: dict[str, Any]) -> dict[str, float] | None:
    """`ramp.Arena` as the page draws it (None when it does not make sense)."""
    try:
        out = {k: float(msg[k]) for k in ("length_m", "width_m", "robot_length_m",
                                           "robot_width_m")}
    except (KeyError, TypeError, ValueError):
        return None
    return out if all(math.isfinite(v) and v > 0 for v in out.values()) else None


class AutonomyLink:
    """The view's connection, reconnecting by itself; `on_update(kind)` after each change
    (kind: "link", "state", "numbers", "pose", "map", "scan")."""

    def __init__(self, host: str, port: int, *, on_update: Callable[[str], None] | None = None,
                 pose_period: float = POSE_PERIOD_S, scan_period: float = SCAN_PERIOD_S,
                 retry: float = RETRY_S) -> None:
        self.host, self.port = host, port
        self.address = f"{host}:{port}"
        self.on_update = on_update
        self.pose_period, self.scan_period, self.retry = pose_period, scan_period, retry
        self.view = ViewState()
        self.bytes_in = 0
        self.bytes_out = 0
        self._stopping = False
        self._ws: Any = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    async def run(self) -> None:
        """Connect, follow the view, report a loss, retry; until `close`."""
        try:
            from websockets.asyncio.client import connect
        except ImportError:
            self._link(False, "the websockets library is missing: pip install 'ramp[teleop]'")
            return
        from websockets.typing import Subprotocol

        while not self._stopping:
            try:
                async with connect(self.url, subprotocols=[Subprotocol(SUBPROTOCOL)],
                                   open_timeout=2.0, max_size=4 << 20, compression=None,
                                   ping_interval=5.0, ping_timeout=5.0) as ws:
                    self._ws = ws
                    self._link(True, f"connected to {self.address}")
                    await self._follow(ws)
                    detail = "the view closed the connection"
            except (OSError, TimeoutError) as exc:
                detail = f"cannot reach {self.address}: " \
                         f"{getattr(exc, 'strerror', None) or exc or type(exc).__name__}"
            except Exception as exc:  # noqa: BLE001 - a bad view must not end the console
                detail = f"{self.address}: {type(exc).__name__}: {exc}"
            self._ws = None
            if self._stopping:
                break
            if self.view.connected or self.view.detail != detail:
                self._link(False, detail)
            await asyncio.sleep(self.retry)

    async def close(self) -> None:
        self._stopping = True
        ws = self._ws
        if ws is not None:
            with contextlib.suppress(Exception):
                await ws.close()

    # -- one connection -----------------------------------------------------------------------
    async def _follow(self, ws: Any) -> None:
        channels: dict[int, str] = {}        # channel id -> topic
        subs: dict[int, str] = {}            # our subscription id -> topic
        by_topic: dict[str, int] = {}        # topic -> our subscription id
        next_sub = iter(range(1, 1 << 31))
        due: dict[str, float] = {}           # sampled topic -> loop time of its next take
        loop = asyncio.get_running_loop()
        periods = {POSE: self.pose_period, TRUE_POSE: self.pose_period,
                   NUMBERS: self.pose_period, SCAN: self.scan_period}

        async def send(obj: dict[str, Any]) -> None:
            text = json.dumps(obj, separators=(",", ":"))
            self.bytes_out += len(text)
            await ws.send(text)

        async def subscribe(topics: list[str]) -> None:
            wanted = [(t, cid) for cid, t in channels.items() if t in topics
                      and t not in by_topic]
            if not wanted:
                return
            pairs = []
            for topic, cid in wanted:
                sid = next(next_sub)
                subs[sid], by_topic[topic] = topic, sid
                pairs.append({"id": sid, "channelId": cid})
            await send({"op": "subscribe", "subscriptions": pairs})

        async def unsubscribe(topics: list[str]) -> None:
            ids = [by_topic.pop(t) for t in topics if t in by_topic]
            for sid in ids:
                subs.pop(sid, None)
            if ids:
                await send({"op": "unsubscribe", "subscriptionIds": ids})

        async def sampler() -> None:
            while True:
                now = loop.time()
                start = [t for t in periods if t in channels.values() and t not in by_topic
                         and now >= due.get(t, 0.0)]
                for t in start:
                    due[t] = now + periods[t]
                await subscribe(start)
                await asyncio.sleep(0.05)

        sampling = asyncio.create_task(sampler())
        try:
            async for message in ws:
                now = loop.time()
                self.bytes_in += len(message)
                if isinstance(message, str):
                    msg = json.loads(message)
                    op = msg.get("op")
                    if op == "advertise":
                        for ch in msg.get("channels") or []:
                            channels[int(ch["id"])] = str(ch["topic"])
                        await subscribe(list(ALWAYS))
                    elif op == "unadvertise":
                        for cid in msg.get("channelIds") or []:
                            channels.pop(int(cid), None)
                    elif op == "status":
                        log.info("autonomy view says: %s", msg.get("message"))
                    continue
                if len(message) < _HEADER.size or message[0] != 0x01:
                    continue
                _, sid, stamp_ns = _HEADER.unpack_from(message)
                topic = subs.get(sid)
                if topic is None:
                    continue  # sent before our unsubscribe arrived
                if topic in periods:
                    # Got the one we wanted: say so at once, not at the sampler's next turn
                    # (scans come several a second while the autonomy looks around).
                    await unsubscribe([topic])
                self.view.last_message = now
                try:
                    payload = json.loads(bytes(message[_HEADER.size:]))
                except ValueError:
                    continue
                self._take(topic, payload, stamp_ns, now)
        finally:
            sampling.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sampling

    def _take(self, topic: str, msg: dict[str, Any], stamp_ns: int, now: float) -> None:
        v = self.view
        if topic == STATE:
            v.state, v.previous = str(msg.get("state", "")), str(msg.get("from", ""))
            v.trigger, v.reason = str(msg.get("trigger", "")), str(msg.get("reason", ""))
            v.localization = str(msg.get("localization", ""))
            age = (time.time_ns() - stamp_ns) / 1e9
            v.state_since = now - age if 0 <= age < 86_400 else now
        elif topic == NUMBERS:
            v.numbers = {k: (None if isinstance(x, float) and not math.isfinite(x) else x)
                         for k, x in msg.items() if isinstance(x, int | float | type(None))}
        elif topic in (POSE, TRUE_POSE):
            pose = msg.get("pose") or {}
            p = pose.get("position") or {}
            value = (round(float(p.get("x", 0.0)), 3), round(float(p.get("y", 0.0)), 3),
                     round(yaw_of(pose.get("orientation") or {}), 4))
            if topic == POSE:
                v.pose = value
            else:
                v.true_pose = value
        elif topic == MAP:
            v.map = map_view(msg, v.map)
            v.map_version += 1
        elif topic == OBSTACLES:
            v.map = dict(v.map, obstacles=obstacles_view(msg))
            v.map_version += 1
        elif topic == ARENA:
            size = arena_view(msg)
            if size is not None:
                v.map = dict(v.map, arena=size,
                             robot=[size["robot_length_m"], size["robot_width_m"]])
                v.map_version += 1
        elif topic == SCAN:
            v.scan = scan_points(msg)
            v.scan_at = now
            v.scan_version += 1
        if self.on_update is not None:
            self.on_update(topic)

    def _link(self, up: bool, detail: str) -> None:
        v = self.view
        v.connected, v.detail = up, detail
        if not up:
            v.pose = v.true_pose = None
        log.info("autonomy view %s: %s", "up" if up else "down", detail)
        if self.on_update is not None:
            self.on_update("link")
