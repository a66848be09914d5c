"""The console's two MCP connections to the robot, each reconnecting by itself.

- The status link polls `robot.get` and every attached module's `get` at a fixed rate and
  asks the robot to describe itself again whenever a module attaches, faults or detaches.
  It never sends motion, and the supervisor counts only the feeder's messages, so polling
  can never keep a motion alive.
- The command link carries what the operator does (calls, STOP, the gamepad's requests and
  their heartbeats), and nothing when the operator does nothing.

A dropped connection is reported at once (the reader sees the close), a silent one when an
answer is `answer_timeout` late; both are closed and retried every `retry` seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ramp.errors import ProtocolError
from ramp.mcp.aio import AsyncMcpClient
from ramp.mcp.describe import Catalog, build_catalog, error_text, value_text
from ramp.mcp.messages import Response
from ramp.mcp.session import Message, Reply

log = logging.getLogger("ramp.teleop")

RETRY_S = 0.5
ANSWER_TIMEOUT_S = 1.0


class Link:
    """One MCP connection that comes back by itself after a loss."""

    def __init__(self, host: str, port: int, role: str, *,
                 on_change: Callable[[bool, str], None] | None = None,
                 retry: float = RETRY_S, answer_timeout: float = ANSWER_TIMEOUT_S,
                 ssl_context: ssl.SSLContext | None = None) -> None:
        self.host, self.port, self.role = host, port, role
        self.ssl_context = ssl_context  # mcps:// (SPEC 13)
        self.retry, self.answer_timeout = retry, answer_timeout
        self.on_change = on_change
        self.client: AsyncMcpClient | None = None
        self.detail = "connecting"
        self._stopping = False
        self._bytes_before = 0  # by the connections closed so far

    @property
    def up(self) -> bool:
        return self.client is not None and not self.client.closed

    async def run(self) -> None:
        """Connect, wait for the connection to end, report, retry; until `stop`."""
        loop = asyncio.get_running_loop()
        while not self._stopping:
            try:
                client = await AsyncMcpClient.connect(self.host, self.port,
                                                      timeout=self.answer_timeout,
                                                      ssl_context=self.ssl_context)
            except ConnectionError as exc:
                if str(exc) != self.detail:  # say why once, not at every retry
                    self.detail = str(exc)
                    self._notify(False)
                await asyncio.sleep(self.retry)
                continue
            self.client = client
            self.detail = f"connected to {self.host}:{self.port}"
            self._notify(True)
            watchdog = asyncio.create_task(self._watch_answers(client, loop))
            await client.wait_closed()
            watchdog.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watchdog
            self.client = None
            self._bytes_before += client.bytes_in + client.bytes_out
            if self._stopping:
                break
            self.detail = f"lost: {client.close_reason}"
            self._notify(False)
            await asyncio.sleep(self.retry)

    async def _watch_answers(self, client: AsyncMcpClient, loop: asyncio.AbstractEventLoop
                             ) -> None:
        """Close a connection whose oldest unanswered message is too old."""
        while not client.closed:
            oldest = client.oldest_sent_at()
            if oldest is not None and loop.time() - oldest > self.answer_timeout:
                log.warning("%s link: no answer within %.1f s; reconnecting", self.role,
                            self.answer_timeout)
                await client.close()
                client.close_reason = f"no answer within {self.answer_timeout:g} s"
                return
            await asyncio.sleep(self.answer_timeout / 4)

    @property
    def bytes_total(self) -> int:
        """Bytes both ways over every connection of this link so far."""
        client = self.client
        now = client.bytes_in + client.bytes_out if client is not None else 0
        return self._bytes_before + now

    def submit(self, message: Message) -> asyncio.Future[Reply[Any]] | None:
        """Write a message now if connected; the future's exception is always retrieved."""
        client = self.client
        if client is None or client.closed:
            return None
        try:
            future = client.submit(message)
        except ConnectionError:
            return None
        future.add_done_callback(_retrieve)
        return future

    async def close(self) -> None:
        self._stopping = True
        if self.client is not None:
            await self.client.close()

    def _notify(self, up: bool) -> None:
        log.info("%s link %s: %s", self.role, "up" if up else "down", self.detail)
        if self.on_change is not None:
            self.on_change(up, self.detail)


def _retrieve(future: asyncio.Future[Any]) -> None:
    if not future.cancelled():
        future.exception()


# --------------------------------------------------------------------------- status


@dataclass
class Status:
    """The robot as the last poll saw it."""

    reachable: bool = False
    detail: str = "connecting"
    rtt_ms: float | None = None
    #: `module:device.property` -> the values as MCP printed them, joined by commas.
    values: dict[str, str] = field(default_factory=dict)
    #: module -> state (`ok`, `fault`, `detached`), from `robot.get`.
    states: dict[str, str] = field(default_factory=dict)
    #: module -> the error its get answered (a fault, say).
    errors: dict[str, str] = field(default_factory=dict)
    polls: int = 0
    #: Loop time at which the last answered poll was sent.
    sent_at: float | None = None

    def view(self) -> dict[str, Any]:
        return {"reachable": self.reachable, "detail": self.detail, "rtt_ms": self.rtt_ms,
                "values": self.values, "states": self.states, "errors": self.errors}


def value_key(r: Response) -> str:
    return f"{r.module}:{r.device}.{r.prop}"


def catalog_view(cat: Catalog, states: dict[str, str]) -> list[dict[str, Any]]:
    """The tree the page draws: modules, their devices, functions and properties."""
    out = []
    for module in cat.modules:
        devices: dict[str, dict[str, Any]] = {}

        def device(name: str, devices: dict[str, dict[str, Any]] = devices) -> dict[str, Any]:
            return devices.setdefault(name, {"name": name, "functions": [], "properties": []})

        for fn in cat.functions.get(module, ()):
            device(fn.device)["functions"].append({"name": fn.name, "params": list(fn.params)})
        for p in cat.properties.get(module, ()):
            device(p.device)["properties"].append({"name": p.name, "type": p.type,
                                                   "unit": p.unit})
        out.append({"name": module, "state": "ok" if module == "robot" else
                    states.get(module, "unknown"), "problem": cat.problems.get(module, ""),
                    "devices": list(devices.values())})
    return out


class StatusPoller:
    """Polls the robot over its own link; keeps `status` and the describe `catalog`."""

    def __init__(self, link: Link, rate_hz: float = 10.0, *,
                 on_status: Callable[[Status], None] | None = None,
                 on_catalog: Callable[[Catalog], None] | None = None) -> None:
        if not 0 < rate_hz <= 100:
            raise ValueError("the poll rate must be in 0 < rate <= 100 Hz")
        self.link, self.period = link, 1.0 / rate_hz
        self.on_status, self.on_catalog = on_status, on_catalog
        self.status = Status()
        self.catalog = Catalog(modules=["robot"])
        self._describes: dict[str, list[Response]] = {}
        self._described_states: dict[str, str] | None = None
        link.on_change = self._link_changed

    def _link_changed(self, up: bool, detail: str) -> None:
        self.status.reachable = up and self.status.reachable
        self.status.detail = detail
        if not up:
            self.status.reachable = False
            self.status.rtt_ms = None
            self._described_states = None
            if self.on_status is not None:
                self.on_status(self.status)

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while True:
            client = self.link.client
            if client is not None and not client.closed:
                with contextlib.suppress(ConnectionError, TimeoutError, ProtocolError):
                    await self.poll_once(client)
            next_at += self.period
            delay = next_at - loop.time()
            if delay < 0:  # behind (a slow answer): skip the missed slots, do not burst
                next_at = loop.time()
                delay = 0
            await asyncio.sleep(delay)

    def poll_message(self) -> str:
        parts = ["robot:robot.get=()"]
        for module in self.catalog.modules:
            if module == "robot" or self.status.states.get(module, "ok") != "ok":
                continue
            if self.catalog.function(module, module, "get") is not None:
                parts.append(f"{module}:{module}.get=()")
        return "".join(parts)

    async def poll_once(self, client: AsyncMcpClient) -> None:
        if self._described_states is None:
            await self.describe(client)
        reply = await client.exchange(self.poll_message(), self.link.answer_timeout)
        rows = reply.responses()
        self.apply(rows, reply.rtt)
        self.status.sent_at = reply.sent_at
        if self.status.states != self._described_states:
            await self.describe(client)
        if self.on_status is not None:
            self.on_status(self.status)

    def apply(self, rows: list[Response], rtt: float | None) -> None:
        """Fold one poll's rows into the status."""
        st = self.status
        st.reachable, st.polls = True, st.polls + 1
        st.detail = f"connected to {self.link.host}:{self.link.port}"
        st.rtt_ms = None if rtt is None else round(rtt * 1000.0, 2)
        modules = set(self.catalog.modules)
        errors: dict[str, str] = {}
        for r in rows:
            if r.prop == "error":
                errors[r.module] = error_text(r)
                continue
            st.values[value_key(r)] = ",".join(value_text(v) for v in r.values)
            if r.module == "robot" and r.prop == "state" and r.device in modules \
                    and r.device != "robot" and r.values:
                st.states[r.device] = value_text(r.values[0])
        st.errors = errors

    async def describe(self, client: AsyncMcpClient) -> None:
        """Ask the robot and every module what they offer; keep the last good answer of each."""
        robot_rows = await client.request("robot:robot.describe=()", self.link.answer_timeout)
        modules = [value_text(r.values[0]) for r in robot_rows
                   if (r.module, r.device, r.prop) == ("robot", "robot", "module") and r.values]
        answers: dict[str, list[Response]] = {}
        if modules:
            message = "".join(f"{m}:{m}.describe=()" for m in modules)
            rows = await client.request(message, self.link.answer_timeout)
            for m in modules:
                mine = [r for r in rows if r.module == m]
                if mine and not any(r.prop == "error" for r in mine):
                    self._describes[m] = mine
                elif m not in self._describes:
                    answers[m] = mine  # never described: show why (not_attached, fault)
        answers.update(self._describes)
        cat = build_catalog(robot_rows, {m: answers.get(m, []) for m in modules})
        self.catalog = cat
        # States as of this describe; the first poll after it fills them in.
        self._described_states = dict(self.status.states)
        if self.on_catalog is not None:
            self.on_catalog(cat)
