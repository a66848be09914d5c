"""The autonomy's command endpoint: how a supervisor (the fleet agent) reaches the mission
without the backend ever hearing of orders (SPEC 14).

JSON lines over TCP on loopback (`ramp-autonomy --command-port P`, `ramp sim mission
--realtime --command-port P`), served from the autonomy's own loop, never blocking it. Each
line in is one command, answered by one line `{"re": CMD, "ok": true|false, "error": ...}`;
twice a second every client also gets `{"status": {...}}`:

    {"cmd": "status"}                           the status now
    {"cmd": "rmcMission"}                       start the RMC mission (see below)
    {"cmd": "pause", "reason": "..."}           hold the mission (it stops and waits)
    {"cmd": "resume"}                           end the hold
    {"cmd": "goto", "x": X, "y": Y, "theta": T, "id": "..."}   drive to a pose (theta
                                                optional, radians; arena frame, m)
    {"cmd": "dig", "seconds": S, "id": "..."}   dig where the robot stands (S optional)
    {"cmd": "dump", "id": "..."}                to the collector, dock, deposit
    {"cmd": "cancel", "reason": "..."}          stop the node task (the robot stops)

status: `state` (the mission machine's), `started`, `held` (why, or null), `over`,
`outcome`, `pose` ({x, y, yaw} in the arena frame, radians; null while lost or unknown),
`confidence` (0..1), `bin_kg`, `delivered_kg`, `has_control`, `task` (the node task: `kind`,
`id`, `state` running|waiting|held|done|failed|cancelled, `step`, `reason`, `target`; null
before the first).

Node tasks (`goto`, `dig`, `dump`: ramp/autonomy/executive/tasks.py) run the mission's own
activities (its localizer, planner, follower, dig and deposit) while the mission is held,
one at a time; they are refused while the RMC mission runs, and `rmcMission` is refused
while one runs. `pause` holds a running task too (the robot stops), `resume` starts a held
task again from its first step (the mission stays held).

With an endpoint, the mission starts held ("waiting for an order") and the run's time starts
when `rmcMission` releases it. Safety: a client that started the mission, or held it, and
then disconnects (an agent that died) leaves the mission held, so the motion it commanded
stops; only a new `resume` or `rmcMission` from a client ends that hold. A client that
started a node task and disconnects cancels it: the robot stops.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import math
import socket
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ramp.statemachine import Mission

if TYPE_CHECKING:
    from ramp.autonomy.executive.kit import Kit
    from ramp.autonomy.executive.tasks import NodeTasks

log = logging.getLogger("ramp.autonomy.command")

STATUS_EVERY_S = 0.5
MAX_LINE = 4096
MAX_CLIENTS = 4
WAITING_FOR_ORDER = "waiting for the fleet's rmcMission order"
TASK_RUNS = "held while the fleet's node tasks run"


class _Client:
    def __init__(self, sock: socket.socket, address: Any) -> None:
        self.sock = sock
        self.address = address
        self.buf = bytearray()
        self.out = bytearray()
        self.commanded = False  # it started or resumed the mission


class CommandEndpoint:
    """The server; `tick(now, dt)` from a scheduler task, readers on the loop."""

    def __init__(self, mission: Mission, *, pose: Callable[[], Any],
                 confidence: Callable[[], float], now: Callable[[], float],
                 host: str = "127.0.0.1", port: int = 0, loop: Any = None,
                 kit: Kit | None = None) -> None:
        self.mission = mission
        self.tasks: NodeTasks | None = None
        if kit is not None:  # node tasks need the executive's kit (ramp-autonomy, the sim)
            from ramp.autonomy.executive.tasks import NodeTasks

            self.tasks = NodeTasks(mission, kit)
        self.pose = pose
        self.confidence = confidence
        self.now = now
        self.loop = loop
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind((host, port))
        self.server.listen(4)
        self.server.setblocking(False)
        self.address: tuple[str, int] = self.server.getsockname()[:2]
        self.clients: list[_Client] = []
        self.dispatched = False
        self._last_status = -math.inf
        mission.hold(WAITING_FOR_ORDER)

    # -- status -----------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        m = self.mission
        ctx = m.context
        est = self.pose()
        pose = None if est is None else {"x": round(est.x, 3), "y": round(est.y, 3),
                                         "yaw": round(est.yaw, 4)}
        return {"state": m.state, "started": self.dispatched, "held": m.held,
                "over": m.over, "outcome": m.outcome, "pose": pose,
                "confidence": round(float(self.confidence()), 3),
                "bin_kg": round(float(ctx.bin_kg), 2),
                "delivered_kg": round(float(ctx.delivered_kg), 2),
                "has_control": m.has_control,
                "task": self.tasks.status() if self.tasks is not None else None}

    # -- commands ---------------------------------------------------------------------------
    def handle(self, client: _Client | None, cmd: Any) -> dict[str, Any]:
        if not isinstance(cmd, dict) or not isinstance(cmd.get("cmd"), str):
            return {"re": None, "ok": False, "error": "expected {\"cmd\": NAME, ...}"}
        name = cmd["cmd"]
        m = self.mission
        if name == "status":
            return {"re": name, "ok": True, "status": self.status()}
        if name == "rmcMission":
            if self.tasks is not None and self.tasks.active:
                return {"re": name, "ok": False, "error": "a node task runs: cancel it first"}
            if self.dispatched and not m.over:
                if m.held is not None:
                    return {"re": name, "ok": False,
                            "error": f"the mission is held ({m.held}): resume it"}
                return {"re": name, "ok": True, "note": "the mission is already running"}
            if m.over:
                return {"re": name, "ok": False, "error": "the mission is over"}
            self.dispatched = True
            budget = m.context.budget
            m.context.budget = dataclasses.replace(budget, start_s=self.now())
            m.release_hold()
            if client is not None:
                client.commanded = True
            return {"re": name, "ok": True}
        if name == "pause":
            reason = str(cmd.get("reason") or "paused by a supervisor")
            m.hold(reason)
            if self.tasks is not None:
                self.tasks.hold(reason)
            return {"re": name, "ok": True}
        if name == "resume":
            if self.tasks is not None and self.tasks.resume():
                # the mission stays held, out of the task's way
                m.hold(WAITING_FOR_ORDER if not self.dispatched else TASK_RUNS)
                if client is not None:
                    client.commanded = True
                return {"re": name, "ok": True, "note": "the node task starts again"}
            if not self.dispatched:
                m.hold(WAITING_FOR_ORDER)
                return {"re": name, "ok": True, "note": "no mission dispatched yet"}
            m.release_hold()
            if client is not None:
                client.commanded = True
            return {"re": name, "ok": True}
        if name in ("goto", "dig", "dump"):
            return self._task(client, name, cmd)
        if name == "cancel":
            reason = str(cmd.get("reason") or "cancelled by a supervisor")
            if self.tasks is None or not self.tasks.cancel(reason):
                return {"re": name, "ok": True, "note": "no node task runs"}
            return {"re": name, "ok": True, "status": self.status()}
        return {"re": name, "ok": False, "error": f"unknown command {name!r}"}

    def _task(self, client: _Client | None, name: str, cmd: dict[str, Any]) -> dict[str, Any]:
        m = self.mission
        if self.tasks is None:
            return {"re": name, "ok": False, "error": f"{name}: this autonomy runs whole RMC "
                    "missions only (rmcMission): it was started without node tasks"}
        if self.dispatched and not m.over and m.held is None:
            return {"re": name, "ok": False, "error": "the RMC mission runs: pause it first"}
        args: dict[str, float | None] = {}
        for key in ("x", "y", "theta", "seconds"):
            value = cmd.get(key)
            if value is None:
                args[key] = None
            elif isinstance(value, int | float) and not isinstance(value, bool) \
                    and math.isfinite(value):
                args[key] = float(value)
            else:
                return {"re": name, "ok": False, "error": f"{key} must be a finite number"}
        if m.held is None:
            m.hold(TASK_RUNS)  # the mission stays out of the way of the task
        why = self.tasks.start(name, str(cmd.get("id") or ""), **args)
        if why:
            return {"re": name, "ok": False, "error": why}
        if client is not None:
            client.commanded = True
        return {"re": name, "ok": True, "status": self.status()}

    # -- I/O --------------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        self._accept()
        if self.tasks is not None:
            try:
                self.tasks.tick(now, dt)
            except Exception as exc:  # a step that raised: the robot stops, the task fails
                log.exception("command endpoint: the node task raised")
                self.tasks.cancel(f"{type(exc).__name__}: {exc}")
                if self.tasks.task is not None:
                    self.tasks.task.state = "failed"
        for c in list(self.clients):
            self._read(c)
        if now - self._last_status >= STATUS_EVERY_S and self.clients:
            self._last_status = now
            line = json.dumps({"status": self.status()}).encode() + b"\n"
            for c in list(self.clients):
                self._send(c, line)

    def _accept(self) -> None:
        while True:
            try:
                sock, address = self.server.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                log.warning("command endpoint: accept failed: %s", exc)
                return
            if len(self.clients) >= MAX_CLIENTS:
                with contextlib.suppress(OSError):
                    sock.sendall(b'{"ok": false, "error": "busy"}\n')
                sock.close()
                continue
            sock.setblocking(False)
            self.clients.append(_Client(sock, address))
            log.info("command endpoint: %s connected", address)

    def _read(self, c: _Client) -> None:
        try:
            data = c.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop(c)
            return
        c.buf += data
        while b"\n" in c.buf:
            raw, _, rest = bytes(c.buf).partition(b"\n")
            c.buf = bytearray(rest)
            try:
                reply = self.handle(c, json.loads(raw))
            except ValueError:
                reply = {"re": None, "ok": False, "error": "not a JSON line"}
            self._send(c, json.dumps(reply).encode() + b"\n")
        if len(c.buf) > MAX_LINE:
            self._send(c, b'{"re": null, "ok": false, "error": "line too long"}\n')
            self._drop(c)

    def _send(self, c: _Client, data: bytes) -> None:
        c.out += data
        try:
            n = c.sock.send(c.out)
            del c.out[:n]
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self._drop(c)
            return
        if len(c.out) > 1 << 20:
            self._drop(c)  # a client that reads nothing

    def _drop(self, c: _Client) -> None:
        if c not in self.clients:
            return
        self.clients.remove(c)
        with contextlib.suppress(OSError):
            c.sock.close()
        if c.commanded and self.tasks is not None and self.tasks.active:
            self.tasks.cancel("the supervisor that commanded the task disconnected")
            log.warning("command endpoint: %s (which commanded a node task) is gone: the "
                        "task is cancelled and the robot stopped", c.address)
        if c.commanded and self.dispatched and not self.mission.over:
            self.mission.hold("the supervisor that commanded the mission disconnected")
            log.warning("command endpoint: %s (which commanded the mission) is gone: the "
                        "mission is held until a supervisor resumes it", c.address)

    def close(self) -> None:
        for c in list(self.clients):
            with contextlib.suppress(OSError):
                c.sock.close()
        self.clients.clear()
        with contextlib.suppress(OSError):
            self.server.close()
