"""`ramp log summary`: what happened in a recorded run, in one screen.

Everything is worked out from the recorded channels alone. Where the supervisor records an
event channel and the health rows carry the same fact (a watchdog trip, a module fault), the
larger count wins, so a file without events (or with health samples too sparse to see a
short trip) still tells the truth.
"""

from __future__ import annotations

import datetime as dt
import re
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from ramp.recorder.reading import FileInfo, Msg
from ramp.recorder.schemas import (
    TOPIC_COMMANDS,
    TOPIC_EVENTS,
    TOPIC_HEALTH,
    TOPIC_LOG,
    TOPIC_MCP_IN,
    TOPIC_MCP_OUT,
    TOPIC_MODULE_STATE,
)

_ERROR_CODE = re.compile(r"[A-Za-z0-9_]+:[A-Za-z0-9_]+\.error=\(([a-z_]+)")
ROBOT_ROWS = {"robot", "tick", "watchdog", "control", "clients", "recorder"}


@dataclass
class _Span:
    """A time a condition held (a module moving, an owner holding control)."""

    total_ns: int = 0
    since: int | None = None

    def update(self, on: bool, t: int) -> bool:
        """Returns True when the condition has just started."""
        if on and self.since is None:
            self.since = t
            return True
        if not on and self.since is not None:
            self.total_ns += t - self.since
            self.since = None
        return False

    def close(self, t: int) -> int:
        return self.total_ns + (t - self.since if self.since is not None else 0)


@dataclass
class Summary:
    """Accumulates messages (`add`), then `report()`s a JSON-able dict."""

    first: int | None = None
    last: int | None = None
    topics: Counter[str] = field(default_factory=Counter)
    clients: dict[str, dict[str, Any]] = field(default_factory=dict)
    errors_sent: Counter[str] = field(default_factory=Counter)
    owners: list[dict[str, Any]] = field(default_factory=list)
    trips_event: list[int] = field(default_factory=list)
    trips_health: list[int] = field(default_factory=list)
    faults_event: dict[str, list[int]] = field(default_factory=lambda: defaultdict(list))
    faults_health: dict[str, list[int]] = field(default_factory=lambda: defaultdict(list))
    events: Counter[str] = field(default_factory=Counter)
    #: Activations per interlock rule (SPEC 11), from the `interlock` events.
    interlocks: Counter[str] = field(default_factory=Counter)
    #: Per identity (SPEC 13 audit): commands, acquires, takeovers, resets, refusals; and
    #: the addresses it spoke from.
    identities: dict[str, Counter[str]] = field(default_factory=dict)
    addresses: dict[str, set[str]] = field(default_factory=lambda: defaultdict(set))
    overruns: list[int] = field(default_factory=list)
    late_max_us: float = 0.0
    battery: dict[str, list[float]] = field(default_factory=dict)
    log_levels: Counter[int] = field(default_factory=Counter)
    log_errors: list[tuple[int, str]] = field(default_factory=list)
    _watchdog: str | None = None
    _owner: str | None = None
    _owner_since: int = 0
    _module_state: dict[str, str] = field(default_factory=dict)
    _health_state: dict[str, str] = field(default_factory=dict)
    _duty: dict[str, dict[str, float]] = field(default_factory=lambda: defaultdict(dict))
    _moving_cmd: dict[str, _Span] = field(default_factory=lambda: defaultdict(_Span))
    _moving_rows: dict[str, _Span] = field(default_factory=lambda: defaultdict(_Span))

    def add(self, msg: Msg) -> None:
        topic, t, data = msg
        self.first = t if self.first is None else min(self.first, t)
        self.last = t if self.last is None else max(self.last, t)
        self.topics[topic] += 1
        if not isinstance(data, dict):
            return
        if topic == TOPIC_MCP_IN:
            c = self.clients.setdefault(str(data.get("client")),
                                        {"messages": 0, "first": t, "last": t})
            c["messages"] += 1
            c["last"] = t
        elif topic == TOPIC_MCP_OUT:
            for code in _ERROR_CODE.findall(str(data.get("line", ""))):
                self.errors_sent[code] += 1
        elif topic == TOPIC_HEALTH:
            self._health(t, data)
        elif topic == TOPIC_COMMANDS:
            if data.get("kind") == "output":
                return  # an LED or a relay: not motion
            channel = str(data.get("channel", ""))
            module = channel.split(".", 1)[0]
            duties = self._duty[module]
            duties[channel] = float(data.get("duty") or 0.0)
            self._moving_cmd[module].update(any(d != 0.0 for d in duties.values()), t)
        elif topic == TOPIC_MODULE_STATE:
            module, state = str(data.get("module")), str(data.get("state"))
            if state == "fault" and self._module_state.get(module) != "fault":
                self.faults_event[module].append(t)
            self._module_state[module] = state
        elif topic == TOPIC_EVENTS:
            kind = str(data.get("kind"))
            self.events[kind] += 1
            if kind == "watchdog_trip":
                self.trips_event.append(t)
            elif kind == "audit":
                self._audit(str(data.get("text", "")))
            elif kind == "interlock":  # "NAME active: ..." or "NAME released"
                name, _, rest = str(data.get("text", "")).partition(" ")
                if not rest.startswith("released"):
                    self.interlocks[name] += 1
        elif topic == TOPIC_LOG:
            level = int(data.get("level", 0))
            self.log_levels[level] += 1
            if level >= 4 and len(self.log_errors) < 10:
                self.log_errors.append((t, str(data.get("message", ""))))
        elif topic.endswith("/get"):
            self._module_rows(topic[1:-4], t, data)

    def _audit(self, text: str) -> None:
        """`IDENTITY PEER OUTCOME REQUEST` (ramp.runtime.recording)."""
        parts = text.split(" ", 3)
        if len(parts) != 4:
            return
        identity, peer, outcome, request = parts
        counts = self.identities.setdefault(identity, Counter())
        self.addresses[identity].add(peer.rsplit(":", 1)[0])
        if outcome != "accepted":
            counts["refusals"] += 1
        elif "control.acquire=" in request:
            counts["acquires"] += 1
            if self._owner not in (None, "none", identity) and not request.endswith(
                    f"({self._owner})"):
                counts["takeovers"] += 1
        elif ".reset=" in request:
            counts["resets"] += 1
        else:
            counts["commands"] += 1

    def _health(self, t: int, data: dict[str, Any]) -> None:
        wd = _get(data, "watchdog", "state")
        if wd == "tripped" and self._watchdog != "tripped":
            self.trips_health.append(t)
        if wd is not None:
            self._watchdog = str(wd)
        owner = _get(data, "control", "owner")
        if owner is not None and owner != self._owner:
            if self._owner not in (None, "none"):
                self.owners[-1]["until"] = t
            if owner != "none":
                self.owners.append({"owner": str(owner), "since": t, "until": None})
            self._owner = str(owner)
        overruns = _get(data, "tick", "overruns")
        if isinstance(overruns, int | float):
            self.overruns.append(int(overruns))
        late = _get(data, "tick", "late")
        if isinstance(late, list) and late and isinstance(late[-1], int | float):
            self.late_max_us = max(self.late_max_us, float(late[-1]))
        for device, props in data.items():
            if device in ROBOT_ROWS or not isinstance(props, dict):
                continue
            state = props.get("state")
            if isinstance(state, str):
                if state == "fault" and self._health_state.get(device) not in (None, "fault"):
                    self.faults_health[device].append(t)
                self._health_state[device] = state

    def _module_rows(self, module: str, t: int, data: dict[str, Any]) -> None:
        moving = False
        for device, props in data.items():
            if not isinstance(props, dict):
                continue
            volt = props.get("volt")
            if isinstance(volt, int | float):
                b = self.battery.setdefault(f"{module}:{device}.volt", [volt, volt, volt])
                b[0], b[1], b[2] = min(b[0], volt), max(b[1], volt), volt
            vel = props.get("vel")
            if isinstance(vel, int | float) and vel != 0:
                moving = True
        self._moving_rows[module].update(moving, t)

    # -- the report ---------------------------------------------------------------------------
    def report(self, files: Iterable[FileInfo] = ()) -> dict[str, Any]:
        start, end = self.first or 0, self.last or 0

        def rel(t: int) -> float:
            return round((t - start) / 1e9, 3)

        modules = sorted(set(self._moving_cmd) | set(self._moving_rows))
        motion = {}
        for m in modules:
            span = self._moving_cmd[m] if m in self._moving_cmd else self._moving_rows[m]
            motion[m] = round(span.close(end) / 1e9, 3)
        fault_modules = sorted(set(self.faults_event) | set(self.faults_health))
        faults = {}
        for m in fault_modules:
            times = max(self.faults_event.get(m, []), self.faults_health.get(m, []), key=len)
            faults[m] = [rel(t) for t in times]
        trips = max(self.trips_event, self.trips_health, key=len)
        dropped = [int(f.metadata["ramp.recorder"]["dropped"]) for f in files
                   if "ramp.recorder" in f.metadata
                   and f.metadata["ramp.recorder"].get("dropped", "").isdigit()]
        return {
            "files": [{"path": str(f.path), "bytes": f.size, "messages": f.messages,
                       "complete": f.complete, "truncated": f.truncated or None}
                      for f in files],
            "start_utc": _utc(start) if self.first is not None else None,
            "duration_s": rel(end),
            "messages": dict(sorted(self.topics.items())),
            "clients": {c: {"messages": v["messages"], "first_s": rel(v["first"]),
                            "last_s": rel(v["last"])} for c, v in self.clients.items()},
            "error_responses": dict(sorted(self.errors_sent.items())),
            "owners": [{"owner": o["owner"], "since_s": rel(o["since"]),
                        "held_s": round(((o["until"] or end) - o["since"]) / 1e9, 3)}
                       for o in self.owners],
            "watchdog_trips": [rel(t) for t in trips],
            "faults": faults,
            "overruns": (self.overruns[-1] - self.overruns[0]) if self.overruns else None,
            "tick_late_max_us": self.late_max_us if self.overruns else None,
            "motion_s": motion,
            "battery": {k: {"min": v[0], "max": v[1], "last": v[2]}
                        for k, v in sorted(self.battery.items())},
            "events": dict(sorted(self.events.items())),
            "interlocks": dict(self.interlocks),
            "identities": {who: {"commands": c["commands"], "acquires": c["acquires"],
                                 "takeovers": c["takeovers"], "resets": c["resets"],
                                 "refusals": c["refusals"],
                                 "addresses": sorted(self.addresses[who])}
                           for who, c in sorted(self.identities.items())},
            "log": {"warnings": self.log_levels[3], "errors": self.log_levels[4]
                    + self.log_levels[5],
                    "first_errors": [{"at_s": rel(t), "message": m}
                                     for t, m in self.log_errors]},
            "recorder_dropped": sum(dropped) if dropped else None,
        }


def _get(data: dict[str, Any], device: str, prop: str) -> Any:
    props = data.get(device)
    return props.get(prop) if isinstance(props, dict) else None


def _utc(ns: int) -> str:
    return dt.datetime.fromtimestamp(ns / 1e9, dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def _duration(s: float) -> str:
    if s < 60:
        return f"{s:.1f} s"
    m, sec = divmod(int(round(s)), 60)
    return f"{s:.1f} s ({m} min {sec:02d} s)"


def _times(ts: list[float], limit: int = 6) -> str:
    shown = ", ".join(f"{t:g} s" for t in ts[:limit])
    return shown + (f", ... ({len(ts) - limit} more)" if len(ts) > limit else "")


def format_report(r: dict[str, Any]) -> str:
    """The report as the lines `ramp log summary` prints."""
    lines = []
    for f in r["files"]:
        state = "complete" if f["complete"] else f"cut short: {f['truncated']}"
        lines.append(f"file       {f['path']} ({f['bytes'] / 1e6:.2f} MB, "
                     f"{f['messages']} messages, {state})")
    lines.append(f"recorded   {r['start_utc'] or '-'}, {_duration(r['duration_s'])}")
    clients = r["clients"]
    lines.append(f"clients    {len(clients)}" + (": " + ", ".join(
        f"{c} ({v['messages']} messages, {v['first_s']:g}-{v['last_s']:g} s)"
        for c, v in clients.items()) if clients else ""))
    if r["error_responses"]:
        lines.append("errors     " + ", ".join(f"{k} {v}" for k, v in
                                              r["error_responses"].items()))
    owners = r["owners"]
    lines.append("owners     " + (", ".join(
        f"{o['owner']} (from {o['since_s']:g} s, {o['held_s']:g} s)" for o in owners)
        if owners else "none (nobody acquired control)"))
    for who, c in r.get("identities", {}).items():
        lines.append(f"identity   {who} from {', '.join(c['addresses'])}: {c['commands']} "
                     f"commands, {c['acquires']} acquires ({c['takeovers']} takeovers), "
                     f"{c['resets']} resets, {c['refusals']} refusals")
    trips = r["watchdog_trips"]
    lines.append(f"watchdog   {len(trips)} trip{'s' if len(trips) != 1 else ''}"
                 + (f" (at {_times(trips)})" if trips else ""))
    faults = r["faults"]
    lines.append("faults     " + ("; ".join(
        f"{m}: {len(ts)} (at {_times(ts)})" for m, ts in faults.items()) if faults else "0"))
    over = r["overruns"]
    lines.append("overruns   " + ("- (no health samples)" if over is None else
                                  f"{over} (tick lateness max {r['tick_late_max_us']:g} us)"))
    motion = r["motion_s"]
    lines.append("motion     " + (", ".join(f"{m} {s:g} s" for m, s in motion.items())
                                  if motion else "-"))
    battery = r["battery"]
    lines.append("battery    " + ("; ".join(
        f"{k}: min {v['min']:g} V, max {v['max']:g} V, last {v['last']:g} V"
        for k, v in battery.items()) if battery else "-"))
    interlocks = r.get("interlocks")
    if interlocks:
        lines.append("interlocks " + ", ".join(
            f"{name} {n} activation{'s' if n != 1 else ''}" for name, n in interlocks.items()))
    lg = r["log"]
    lines.append(f"log        {lg['warnings']} warning{'s' if lg['warnings'] != 1 else ''}, "
                 f"{lg['errors']} error{'s' if lg['errors'] != 1 else ''}")
    for e in lg["first_errors"]:
        lines.append(f"             {e['at_s']:g} s: {e['message']}")
    if r["recorder_dropped"] is not None:
        lines.append(f"recorder   {r['recorder_dropped']} records dropped")
    return "\n".join(lines)
