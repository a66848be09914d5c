"""The console: pages on one side, the robot's two MCP links on the other, the controller between.

Everything runs in one asyncio loop. Pages post JSON messages (inputs at ~20 Hz, calls,
STOP, control, profile); the console answers each page and broadcasts the robot's status at
the poll rate. The controller decides what motion goes out; this file only moves its
messages and the robot's answers, and reads the loop's monotonic clock.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import math
import re
import ssl
from collections.abc import Callable
from typing import Any

from ramp.mcp.describe import READ_FUNCTIONS, Catalog, error_text
from ramp.mcp.messages import Request, Response
from ramp.mcp.protocol import format_requests, parse_message
from ramp.mcp.session import Reply
from ramp.teleop.alerts import ConsoleAlerts, Inputs, active_interlocks, latch_flags, raised
from ramp.teleop.autonomy import AutonomyLink
from ramp.teleop.controller import Controller, Message, module_stop
from ramp.teleop.gate import PROBE, MotionGate
from ramp.teleop.mapping import PadState, intent_of
from ramp.teleop.profile import Profile, ProfileError, ProfileLibrary
from ramp.teleop.robot import Link, Status, StatusPoller, catalog_view

log = logging.getLogger("ramp.teleop")

TICK_S = 0.05
CALL_TIMEOUT_S = 1.0
STOP_ALL = "robot:robot.stop=()"
_SPLIT_PARAMS = re.compile(r"[,\s]+")
_MAX_KEYS = 16
_DEVICE = re.compile(r"[A-Za-z0-9_]{1,32}:[A-Za-z0-9_]{1,32}\Z")

Sink = Callable[[dict[str, Any]], None]


def call_text(target: str, params: str) -> str:
    """`base:base.drive` and `50, 0` (commas or blanks) -> `base:base.drive=(50,0)`."""
    parts = [p for p in _SPLIT_PARAMS.split(params.strip()) if p]
    return f"{target}=({','.join(parts)})"


def is_motion(r: Request, catalog: Catalog | None = None) -> bool:
    """A request that may set something moving on a module (and so needs a stop later): its
    kind as the robot's describe says (`motion`), or, for a robot that does not say, any
    request that is neither a read nor a stop. Robot-level requests move nothing."""
    if r.module == "robot":
        return False
    if catalog is not None:
        return catalog.kind_of(r.module, r.device, r.function) == "motion"
    return r.function not in READ_FUNCTIONS and r.function != "stop"


def battery_keys(cat: Catalog) -> tuple[str, ...]:
    """Each battery's reading for the low-battery alert: its charge in % where the robot
    gives one (its own battery model), else its volts (the console's `--battery` range)."""
    out: list[str] = []
    props = [p for ps in cat.properties.values() for p in ps]
    charged = {(p.module, p.device) for p in props if p.unit == "%" and p.name == "charge"}
    for p in props:
        if (p.unit == "%" and p.name == "charge") or \
                (p.unit == "V" and (p.module, p.device) not in charged):
            out.append(f"{p.module}:{p.device}.{p.name}")
    return tuple(out)


def refused_modules(requests: list[Request], responses: list[Response]) -> set[str]:
    """Modules whose requests in this message the robot refused (errors echo the module)."""
    sent = {r.module for r in requests}
    return {r.module for r in responses if r.prop == "error" and r.module in sent}


def pad_from_json(data: Any) -> PadState | None:
    """A pad the page read, if it has the standard mapping; None otherwise."""
    if not isinstance(data, dict) or data.get("mapping") != "standard":
        return None
    axes_in, buttons_in = data.get("axes"), data.get("buttons")
    if not isinstance(axes_in, list) or not isinstance(buttons_in, list):
        return None
    axes = tuple(_finite(a) for a in axes_in[:16])
    values: list[float] = []
    pressed: list[bool] = []
    for b in buttons_in[:32]:
        if isinstance(b, list | tuple) and len(b) == 2:
            pressed.append(bool(b[0]))
            values.append(_finite(b[1]))
        else:
            v = _finite(b)
            pressed.append(v >= 0.5)
            values.append(v)
    return PadState(axes, tuple(values), tuple(pressed))


def _finite(x: Any) -> float:
    if isinstance(x, bool):
        return float(x)
    if isinstance(x, int | float) and math.isfinite(x):
        return max(-1.0, min(1.0, float(x)))
    return 0.0


class Console:
    """One operator station: the links, the controller, the open pages."""

    def __init__(self, host: str, port: int, *, name: str, library: ProfileLibrary,
                 profile: Profile, poll_hz: float = 10.0,
                 battery: tuple[float, float] = (17.0, 21.0),
                 autonomy: tuple[str, int] | None = None,
                 ssl_context: ssl.SSLContext | None = None) -> None:
        self.host, self.port, self.name = host, port, name
        self.library, self.profile = library, profile
        self.poll_hz, self.battery = poll_hz, battery
        self.status_link = Link(host, port, "status", ssl_context=ssl_context)
        self.command_link = Link(host, port, "command", on_change=self._command_link_changed,
                                 ssl_context=ssl_context)
        self.poller = StatusPoller(self.status_link, poll_hz, on_status=self._on_status,
                                   on_catalog=self._on_catalog)
        self.controller = Controller(stop_for=self._stop_for)
        self.gate = MotionGate()
        self.pages: dict[str, Sink] = {}
        self._drive_views: dict[str, dict[str, object]] = {}
        self._next_page = 0
        self._tasks: list[asyncio.Task[None]] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        #: The operator took control and has not handed it back: re-taken after a reconnect.
        self.want_control = False
        self._watchdog_state = ""
        #: The autonomy's live view (SPEC 7.1), when `--autonomy` names one.
        self.autonomy = AutonomyLink(*autonomy, on_update=self._on_autonomy) \
            if autonomy is not None else None
        self.alerts = ConsoleAlerts()
        self._bandwidth: dict[str, Any] = {}
        self._counted: tuple[float, int, int] | None = None  # (time, mcp bytes, view bytes)
        self._started_at = 0.0
        self._interlocks: set[str] = set()
        self._mission_state = ""

    # -- lifecycle ------------------------------------------------------------------------------
    def now(self) -> float:
        assert self._loop is not None
        return self._loop.time()

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._tasks = [
            asyncio.create_task(self.status_link.run(), name="status link"),
            asyncio.create_task(self.command_link.run(), name="command link"),
            asyncio.create_task(self.poller.run(), name="status poller"),
            asyncio.create_task(self._tick_loop(), name="controller tick"),
            asyncio.create_task(self._bandwidth_loop(), name="bandwidth"),
        ]
        if self.autonomy is not None:
            self._tasks.append(asyncio.create_task(self.autonomy.run(), name="autonomy view"))
        self._started_at = self.now()

    async def stop(self) -> None:
        """Stop what this console moved, then close both links."""
        self._send(self.controller.halt(self.now(), "console shutting down"))
        client = self.command_link.client
        if client is not None and client.in_flight:
            with contextlib.suppress(asyncio.TimeoutError, ConnectionError):
                await asyncio.wait_for(client.heartbeat(), 0.5)
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        await self.command_link.close()
        await self.status_link.close()
        if self.autonomy is not None:
            await self.autonomy.close()

    # -- pages ----------------------------------------------------------------------------------
    def open_page(self, sink: Sink) -> str:
        self._next_page += 1
        page = str(self._next_page)
        self.pages[page] = sink
        self.controller.open_page(page, self.now())
        sink(self.hello())
        sink(self.catalog_message())
        sink(self.status_message(self.poller.status))
        if self.autonomy is not None:
            view = self.autonomy.view
            sink({"type": "autonomy_map", "map": view.map})
            sink({"type": "autonomy_scan", "points": view.scan})
            sink(self.autonomy_message())
        sink({"type": "alerts", "alerts": self.alerts.view()})
        if self._bandwidth:
            sink(self._bandwidth)
        return page

    def close_page(self, page: str) -> None:
        self.pages.pop(page, None)
        self._drive_views.pop(page, None)
        self.controller.close_page(page, self.now())
        self._run_tick()

    def hello(self) -> dict[str, Any]:
        return {"type": "hello", "name": self.name, "backend": f"{self.host}:{self.port}",
                "poll_hz": self.poll_hz, "battery": list(self.battery),
                "profiles": self.library.names(), "profile": self.profile.summary(),
                "autonomy": self.autonomy.address if self.autonomy is not None else None,
                "safety": {"stale_after": self.controller.stale_after,
                           "focus_grace": self.controller.focus_grace}}

    def page_input(self, page: str, msg: dict[str, Any], at: float | None = None) -> None:
        """An input frame (pad, keys, focus) that arrived at loop time `at`: applied at once,
        and the page's freshness is that arrival, not now."""
        if page not in self.pages:
            return
        keys = [k for k in msg.get("keys", []) if isinstance(k, str)][:_MAX_KEYS] \
            if isinstance(msg.get("keys"), list) else []
        intent = intent_of(self.profile, pad_from_json(msg.get("pad")), keys)
        self.controller.page_input(page, self.now() if at is None else at,
                                   focused=bool(msg.get("focused", True)), intent=intent)
        self._run_tick()

    async def page_message(self, page: str, msg: Any, at: float | None = None) -> None:
        """One message from a page; malformed ones are answered with an event, never fatal."""
        if not isinstance(msg, dict) or page not in self.pages:
            return
        kind = msg.get("type")
        if kind == "input":
            self.page_input(page, msg, at)
            return
        self.controller.seen(page, self.now() if at is None else at)
        if kind == "stop":
            await self.stop_all(page)
        elif kind == "call":
            await self.call(page, msg)
        elif kind == "control":
            await self.control(page, str(msg.get("action", "")))
        elif kind == "profile":
            self.switch_profile(page, str(msg.get("name", "")))
        elif kind == "reset":
            await self.reset(page, str(msg.get("target", "")))
        else:
            self._post(page, {"type": "event", "level": "warning",
                              "text": f"unknown page message {kind!r}"})

    def busy(self, page: str, msg: dict[str, Any]) -> None:
        """Too many of the page's calls wait for answers: this one is not sent."""
        self._post(page, {"type": "result", "id": msg.get("id"), "ok": False,
                          "text": "busy: too many calls waiting for the robot; not sent"})

    # -- operator actions -----------------------------------------------------------------------
    async def stop_all(self, page: str) -> None:
        """The big STOP: `robot:robot.stop=()` on whichever link is up, and latch."""
        self._interrupted("STOP pressed")
        future = self.command_link.submit(STOP_ALL) or self.status_link.submit(STOP_ALL)
        if future is None:
            self._post(page, {"type": "result", "id": "stop", "ok": False,
                              "text": "robot link down: STOP not sent"})
            return
        self._broadcast({"type": "event", "level": "stop", "text": "STOP sent"})
        await self._answer(page, "stop", STOP_ALL, future)

    async def call(self, page: str, msg: dict[str, Any]) -> None:
        call_id = msg.get("id")
        target, params = str(msg.get("target", "")), str(msg.get("params", ""))
        text = call_text(target, params)
        parsed = parse_message(text.encode("ascii", "replace"))
        if parsed.syntax_error is not None or len(parsed.requests) != 1:
            detail = error_text(parsed.syntax_error) if parsed.syntax_error else "one request"
            self._post(page, {"type": "result", "id": call_id, "ok": False, "text": detail})
            return
        request = parsed.requests[0]
        future = self.command_link.submit(request)
        if future is None:
            self._post(page, {"type": "result", "id": call_id, "ok": False,
                              "text": "robot link down: not sent"})
            return
        rows = await self._answer(page, call_id, text, future)
        if rows is None:
            return
        refused = refused_modules([request], rows)
        if (request.module, request.device, request.function) == \
                ("robot", "control", "acquire") and not refused:
            self.want_control = True
            self._interrupted("control taken")
        elif (request.module, request.device, request.function) == \
                ("robot", "control", "release") and not refused:
            self.want_control = False
        elif request.function == "stop" and not refused:
            if request.module == "robot":
                self._interrupted("robot stopped")
            else:
                self.controller.forget([request.module])
        elif is_motion(request, self.poller.catalog) and not refused:
            self.controller.commanded(page, [request.module], self.now())

    async def control(self, page: str, action: str) -> None:
        if action == "acquire":
            await self.call(page, {"id": "control", "target": "robot:control.acquire",
                                   "params": self.name})
        elif action == "release":
            await self.call(page, {"id": "control", "target": "robot:control.release",
                                   "params": ""})

    async def reset(self, page: str, target: str) -> None:
        """An alert's Reset: `MODULE:DEVICE.reset=()`, acknowledging a latched fault."""
        if not _DEVICE.match(target):
            self._post(page, {"type": "result", "id": "reset", "ok": False,
                              "text": f"reset: {target!r} is not MODULE:DEVICE"})
            return
        await self.call(page, {"id": "reset", "target": f"{target}.reset", "params": ""})

    def switch_profile(self, page: str, name: str) -> None:
        try:
            profile = self.library.load(name)
        except ProfileError as exc:
            self._post(page, {"type": "profile_error", "text": str(exc)})
            return
        self._send(self.controller.halt(self.now(), "profile switched"))
        self.profile = profile
        log.info("profile %s (%s)", profile.name, profile.source)
        self._broadcast({"type": "profile", "profiles": self.library.names(),
                         "profile": profile.summary()})

    # -- robot side -----------------------------------------------------------------------------
    def _stop_for(self, module: str) -> Request:
        cat = self.poller.catalog
        if cat.function(module, module, "stop") is not None or module not in cat.modules:
            return module_stop(module)
        return Request("robot", "robot", "stop")

    def _interrupted(self, reason: str) -> None:
        """The robot was stopped: nothing held goes out, driving latches until re-pressed."""
        self.gate.cancel()
        self.controller.interrupted(self.now(), reason)

    def _command_link_changed(self, up: bool, detail: str) -> None:
        if not up:
            self.gate.cancel()
        self.controller.set_link(up, self.now())
        self._broadcast({"type": "event", "level": "info" if up else "error",
                         "text": f"command link {'up' if up else 'lost'}: {detail}"})
        if up and self.want_control:
            future = self.command_link.submit(f"robot:control.acquire=({self.name})")
            if future is not None:
                future.add_done_callback(self._reacquired)

    def _reacquired(self, future: asyncio.Future[Reply[Any]]) -> None:
        ok = not future.cancelled() and future.exception() is None
        text = "control taken again after reconnecting" if ok else "could not take control again"
        self._broadcast({"type": "event", "level": "info" if ok else "error", "text": text})

    def _on_status(self, status: Status) -> None:
        state = status.values.get("robot:watchdog.state", "")
        if state == "tripped" and self._watchdog_state not in ("", "tripped"):
            # A trip seen by a poll sent before our last motion may be an older one that our
            # motion has already re-armed (polls and commands travel on different
            # connections); a later one stopped us, and nothing resumes by itself.
            fresh = status.sent_at is not None and \
                status.sent_at > self.controller.last_motion_at + 0.05
            if fresh:
                self._interrupted("watchdog tripped")
        self._watchdog_state = state
        self._note_interlocks(status)
        self._broadcast(self.status_message(status))
        self._push_drive_views()
        self._update_alerts()

    def _note_interlocks(self, status: Status) -> None:
        """Each activation and release of an interlock is a line in Events; an `info` rule
        (normal work, SPEC 11) is only that, never an alert."""
        now = set(active_interlocks(status.values)) if status.reachable else self._interlocks
        rules = self.poller.catalog.interlocks
        for name in sorted(now ^ self._interlocks):
            rule = rules.get(name)
            severity = rule.severity if rule is not None else "warning"
            on = name in now
            text = f"interlock {name} {'active' if on else 'released'} ({severity})"
            if on and rule is not None and rule.message:
                text += f": {rule.message}"
            self._broadcast({"type": "event", "level": "info" if severity == "info" or not on
                             else "warning", "text": text})
        self._interlocks = now

    # -- the autonomy's view, alerts, bandwidth -------------------------------------------------
    def autonomy_message(self) -> dict[str, Any]:
        assert self.autonomy is not None
        return {"type": "autonomy", "address": self.autonomy.address,
                **self.autonomy.view.summary(self.now())}

    def _on_autonomy(self, kind: str) -> None:
        assert self.autonomy is not None
        view = self.autonomy.view
        if kind in ("/map", "/obstacles", "/arena"):
            self._broadcast({"type": "autonomy_map", "map": view.map})
        elif kind == "/lidar/scan":
            self._broadcast({"type": "autonomy_scan", "points": view.scan})
        elif kind == "/mission/state" and view.state != self._mission_state:
            self._mission_state = view.state
            self._broadcast({"type": "event", "level": "info",
                             "text": f"mission: {view.previous or '?'} -> {view.state}"
                                     f"{' (' + view.reason + ')' if view.reason else ''}"})
        self._broadcast(self.autonomy_message())
        self._update_alerts()

    def _update_alerts(self) -> None:
        status = self.poller.status
        cat = self.poller.catalog
        inputs = Inputs(robot_reachable=status.reachable or status.polls == 0,
                        robot_detail=status.detail, values=status.values, states=status.states,
                        errors=status.errors, batteries=battery_keys(cat),
                        battery_range=self.battery, operator=self.name,
                        interlocks=cat.interlocks, latches=latch_flags(cat),
                        autonomy=None if self.autonomy is None else
                        self.autonomy.view.summary(self.now()))
        if self.alerts.update(raised(inputs), self.now()):
            self._broadcast({"type": "alerts", "alerts": self.alerts.view()})

    async def _bandwidth_loop(self) -> None:
        while True:
            await asyncio.sleep(1.0)
            try:
                self._count_bandwidth()
                if self.autonomy is not None:  # "stale" and "in state" move with time
                    self._broadcast(self.autonomy_message())
                    self._update_alerts()
            except Exception:  # never end the loop that keeps the page's figures
                log.exception("bandwidth count failed")

    def link_bytes(self) -> tuple[int, int]:
        """Bytes both ways so far: (MCP, both links; the autonomy's view)."""
        mcp = self.status_link.bytes_total + self.command_link.bytes_total
        view = 0 if self.autonomy is None else self.autonomy.bytes_in + self.autonomy.bytes_out
        return mcp, view

    def _count_bandwidth(self) -> None:
        now = self.now()
        mcp, view = self.link_bytes()
        if self._counted is not None:
            t0, mcp0, view0 = self._counted
            dt = max(1e-3, now - t0)
            elapsed = max(1e-3, now - self._started_at)
            self._bandwidth = {"type": "bandwidth", "mcp_bps": round((mcp - mcp0) / dt),
                               "view_bps": round((view - view0) / dt),
                               "total_bps": round((mcp + view - mcp0 - view0) / dt),
                               "average_bps": round((mcp + view) / elapsed),
                               "autonomy": self.autonomy is not None}
            self._broadcast(self._bandwidth)
        self._counted = (now, mcp, view)

    def _on_catalog(self, catalog: Catalog) -> None:
        self._broadcast(self.catalog_message())

    def catalog_message(self) -> dict[str, Any]:
        """The tree the page draws, and the interlock rules it names in the robot panel."""
        cat = self.poller.catalog
        return {"type": "catalog", "modules": catalog_view(cat, self.poller.status.states),
                "interlocks": {n: {"severity": r.severity, "message": r.message}
                               for n, r in cat.interlocks.items()}}

    def status_message(self, status: Status) -> dict[str, Any]:
        owner = status.values.get("robot:control.owner", "")
        return {"type": "status", **status.view(),
                "command_link": {"up": self.command_link.up,
                                 "detail": self.command_link.detail},
                "control": {"owner": owner, "mine": self.want_control and owner == self.name,
                            "want": self.want_control}}

    # -- the tick -------------------------------------------------------------------------------
    async def _tick_loop(self) -> None:
        while True:
            try:
                self._run_tick()
            except Exception:  # a bug here must not end the ticks that stop a dead page
                log.exception("controller tick failed")
            await asyncio.sleep(TICK_S)

    def _run_tick(self) -> None:
        self._send(self.controller.tick(self.now()))
        self._push_drive_views()

    def _send(self, messages: list[Message]) -> None:
        for message in messages:
            now_message, probe = self.gate.offer(message)
            if probe:
                future = self.command_link.submit(PROBE)
                if future is None:
                    self.gate.answered(None)
                else:
                    future.add_done_callback(self._probed)
            if now_message is not None:
                self._submit(now_message)

    def _submit(self, message: Message) -> None:
        future = self.command_link.submit(message)
        if future is not None and message:
            future.add_done_callback(functools.partial(self._check_motion_reply, message))

    def _probed(self, future: asyncio.Future[Reply[Any]]) -> None:
        """The check before held motion: send it, or latch when someone stopped us."""
        rows = None
        if not future.cancelled() and future.exception() is None:
            with contextlib.suppress(Exception):
                rows = future.result().responses()
        held, why = self.gate.answered(rows)
        if held is not None:
            self._submit(held)
            return
        if why and rows is not None:
            self.controller.interrupted(self.now(), why)
            self._broadcast({"type": "event", "level": "warning",
                             "text": f"driving latched: {why}; release the dead-man and "
                                     "press it again to drive"})
            self._push_drive_views()

    def _check_motion_reply(self, message: Message, future: asyncio.Future[Reply[Any]]) -> None:
        if future.cancelled() or future.exception() is not None:
            return
        try:
            rows = future.result().responses()
        except Exception:  # a garbled answer: the link's reader will report the connection
            return
        refused = refused_modules(message, rows)
        if refused:
            self.controller.forget(refused)
            self.gate.forget(refused)
            errors = "; ".join(f"{r.module}:{r.device} {error_text(r)}" for r in rows
                               if r.prop == "error")
            self._broadcast({"type": "event", "level": "error",
                             "text": f"refused {format_requests(message).decode().strip()}: "
                                     f"{errors}"})

    def _push_drive_views(self) -> None:
        now = self.now()
        for page in list(self.pages):
            view = self.controller.page_view(page, now)
            if view != self._drive_views.get(page):
                self._drive_views[page] = view
                self._post(page, {"type": "drive", **view})

    # -- output ---------------------------------------------------------------------------------
    async def _answer(self, page: str, call_id: Any, text: str,
                      future: asyncio.Future[Reply[Any]]) -> list[Response] | None:
        try:
            reply = await asyncio.wait_for(asyncio.shield(future), CALL_TIMEOUT_S)
            rows = reply.responses()
        except Exception as exc:  # timeout, lost link, garbled answer: shown to the operator
            self._post(page, {"type": "result", "id": call_id, "ok": False, "request": text,
                              "text": f"{type(exc).__name__}: {exc}"})
            return None
        errors = [r for r in rows if r.prop == "error"]
        shown = "; ".join(f"{r.module}:{r.device}.{r.prop}=({','.join(map(str, r.values))})"
                          for r in rows if r.prop != "error")
        self._post(page, {"type": "result", "id": call_id, "request": text, "ok": not errors,
                          "text": "; ".join(error_text(r) for r in errors) or shown or "ok"})
        return rows

    def _post(self, page: str, message: dict[str, Any]) -> None:
        sink = self.pages.get(page)
        if sink is not None:
            sink(message)

    def _broadcast(self, message: dict[str, Any]) -> None:
        for sink in list(self.pages.values()):
            sink(message)
