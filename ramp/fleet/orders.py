"""Orders for a robot with the autonomy (SPEC 14), run through the autonomy's command
endpoint (ramp/autonomy/command.py; the design is in docs/operating/fleet.md).

What runs: a VDA 5050 2.1.0 order whose nodes carry positions in the arena frame
(`mapId` "arena", SPEC 6.1: x along the arena from the collector wall, y across, theta in
radians, optional). Only the base (the released nodes at the front of the order) is driven;
the horizon (unreleased nodes) is reported in `nodeStates` and waits for an update. Node by
node, the agent asks the autonomy for one node task at a time:

- to reach a node: `goto` (x, y, theta): the autonomy's own localizer and planner (the 3D
  scan first if the node lies beyond the start region and the robot has no obstacle map);
- a node's actions, in order: `dig` (where the robot stands; its front must be in the
  digging region; parameter `seconds`, optional: dig at most that long, else until the bin
  is full), `dump` (the node must be the collector, x within `DUMP_NEAR_M` of the docked
  pose: the autonomy drives there itself, docks and deposits, so the node counts as reached
  once it has docked), `rmcMission` (the whole RMC mission from there: the order's last
  action).

`state`: `nodeStates` and `edgeStates` are what is still to be traversed (a node leaves when
reached, the edge to it with it), `lastNodeId`/`lastNodeSequenceId` the last node reached,
`actionStates` every action of the base WAITING -> INITIALIZING -> RUNNING -> FINISHED or
FAILED with a `resultDescription`. A node the robot cannot reach (no way there, lost) fails
the order: a `noRouteError` says why, the remaining actions are FAILED ("not run"). A failed
action stops the order the same way.

Refused with an `orderError` that says why (nothing of the old order changes): a node
without a position (except a one-node order, whose node is where the robot stands), a
position outside the arena or on another map, an action the robot does not know, `dump`
away from the collector, `rmcMission` before the last action, a released node after the
horizon began, a new order while one runs (cancelOrder first). Order updates (same
`orderId`, higher `orderUpdateId`) are stitched at the last base node (its `nodeId` and
`sequenceId` begin the update; the stitching node's actions are not run twice); an update
that does not begin there is refused with an `orderUpdateError`, a lower `orderUpdateId`
too; the same one again is a repeat and ignored.

Safety: a task is sent to the autonomy only while nobody else holds control (control free
or the autonomy's): under an operator it waits, and `state` says so; a fleet pause refuses
orders and holds the task (the autonomy's `pause`; `startPause` starts it again);
`cancelOrder` cancels the task (the robot stops where it is) or holds the mission.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from ramp.fleet import mapping
from ramp.fleet import vda5050 as v

RMC, DIG, DUMP, GOTO = "rmcMission", "dig", "dump", "goto"
ACTIONS = (RMC, DIG, DUMP)
#: SPEC 6.1's arena (the autonomy's `ramp.autonomy.arena`, which the fleet does not import;
#: a test checks both agree).
ARENA_LENGTH_M = 7.38
ARENA_WIDTH_M = 3.88
#: Where the robot stands docked: its rear on the x = 0 wall, on the collector's line.
COLLECTOR_XY = (0.6, 1.94)
DUMP_NEAR_M = 0.75


@dataclass
class Work:
    """One thing the order asks: reach a node (`goto`) or run one of its actions."""

    kind: str
    node: int  # index in the order's nodes
    action: v.Action | None = None
    status: str = v.WAITING
    result: str = ""
    task_id: str = ""


@dataclass
class Running:
    """The order in hand, and how far it got."""

    order: v.Order
    work: list[Work] = field(default_factory=list)
    index: int = 0  # the work item going on (== len(work) when all is done)
    dispatched: bool = False
    reached: int = -1  # index of the last node reached
    over: bool = False  # finished, failed or cancelled
    closed: bool = False  # failed or cancelled: nothing left to traverse
    failure: dict[str, Any] | None = None  # the error of a failed order, kept in state
    seq_at_receive: int = 0

    @property
    def current(self) -> Work | None:
        return self.work[self.index] if self.index < len(self.work) else None


def base_length(order: v.Order) -> int:
    n = 0
    while n < len(order.nodes) and order.nodes[n].released:
        n += 1
    return n


def check(order: v.Order) -> str:
    """Why the order cannot run here ("" when it can)."""
    nodes = order.nodes
    base = base_length(order)
    if base == 0:
        return "the order has no released node (only a horizon): nothing to drive"
    if any(n.released for n in nodes[base:]):
        return "a released node follows an unreleased one: the base must come first"
    for i, n in enumerate(nodes):
        where = f"node {n.node_id!r}"
        if n.x is None or n.y is None:
            if len(nodes) > 1:
                return (f"{where} has no nodePosition: this robot drives to positions in the "
                        f"arena frame (mapId {v.MAP_ID!r}, x 0..{ARENA_LENGTH_M:g}, "
                        f"y 0..{ARENA_WIDTH_M:g} m)")
        else:
            map_id = n.raw.get("nodePosition", {}).get("mapId", v.MAP_ID)
            if map_id != v.MAP_ID:
                return f"{where} is on map {map_id!r}; this robot knows only {v.MAP_ID!r}"
            if not (0.0 <= n.x <= ARENA_LENGTH_M and 0.0 <= n.y <= ARENA_WIDTH_M):
                return (f"{where} at x {n.x:g} y {n.y:g} is outside the arena (x 0.."
                        f"{ARENA_LENGTH_M:g}, y 0..{ARENA_WIDTH_M:g} m)")
        for j, a in enumerate(n.actions):
            if a.action_type not in ACTIONS:
                return (f"{where}: unsupported action {a.action_type!r}; node actions here "
                        f"are {', '.join(ACTIONS)}")
            if a.action_type == DUMP and n.x is not None and n.y is not None and \
                    math.hypot(n.x - COLLECTOR_XY[0], n.y - COLLECTOR_XY[1]) > DUMP_NEAR_M:
                return (f"{where}: dump is done at the collector (x {COLLECTOR_XY[0]:g} y "
                        f"{COLLECTOR_XY[1]:g}), not at x {n.x:g} y {n.y:g}")
            if a.action_type == DIG and "seconds" in a.parameters:
                s = a.parameters["seconds"]
                if isinstance(s, bool) or not isinstance(s, int | float) or not s > 0:
                    return f"{where}: dig's seconds must be a positive number"
            last = i == base - 1 and j == len(n.actions) - 1
            if a.action_type == RMC and not last:
                return (f"{where}: rmcMission runs the whole mission: it must be the last "
                        "action of the base")
    return ""


def plan_work(order: v.Order, first: int, prefix: str) -> list[Work]:
    """The work of the base nodes from index `first` on."""
    out: list[Work] = []
    for i in range(first, base_length(order)):
        n = order.nodes[i]
        kinds = [a.action_type for a in n.actions]
        if n.x is not None and n.y is not None and DUMP not in kinds:
            out.append(Work(GOTO, i, task_id=f"{prefix}/{n.node_id}/{n.sequence_id}"))
        for a in n.actions:
            out.append(Work(a.action_type, i, a, task_id=a.action_id))
    return out


def _node(run: Running, work: Work) -> v.OrderNode | None:
    nodes = run.order.nodes
    return nodes[work.node] if 0 <= work.node < len(nodes) else None


class Orders:
    """The order the robot runs (one at a time), and its states for `state`."""

    def __init__(self, agent: Any, autonomy: Any) -> None:
        self.agent = agent
        self.autonomy = autonomy
        self.run: Running | None = None
        self.waiting_reason = ""

    # -- what the agent asks ------------------------------------------------------------------
    @property
    def active(self) -> bool:
        """An order is in hand (waiting or running)."""
        return self.run is not None and not self.run.over

    @property
    def running(self) -> bool:
        """The fleet's order is driving the robot (SEMIAUTOMATIC)."""
        st = self.autonomy.status
        run = self.run
        if not (self.active and run is not None and st):
            return False
        if not run.dispatched:  # between one node's work and the next, nothing waited for
            return run.index > 0 and not run.over and not self.waiting_reason
        work = run.current
        if work is not None and work.kind == RMC:
            return not st.get("held") and not st.get("over")
        task = st.get("task") or {}
        # "done" with the order still in hand: between one node's task and the next
        return task.get("state") in ("running", "done")

    def factsheet_actions(self) -> list[dict[str, Any]]:
        return [
            v.agv_action(RMC, "the whole RMC mission (dig, return, deposit, until the run's "
                         "time is nearly out), by the autonomy's own planner and localizer, "
                         "from where the robot stands; the last action of an order",
                         ["INSTANT", "NODE"], result="delivered kg"),
            v.agv_action(DIG, "lower the bucket ladder and dig where the robot stands (its "
                         "front in the digging region), creeping forward, until the bin is "
                         "full or for the given seconds", ["NODE"],
                         [("seconds", "FLOAT", "dig at most this long (default: until the bin "
                           "is full, at most the autonomy's dig_max_s)", True)],
                         result="kg in the bin"),
            v.agv_action(DUMP, "at the collector node (x 0.6, y 1.94): the autonomy drives "
                         "there, docks on the buttons, raises the bin until it is empty and "
                         "drives clear", ["NODE"], result="kg out of the bin"),
        ]

    # -- orders -------------------------------------------------------------------------------
    def receive(self, msg: dict[str, Any]) -> None:
        order = v.parse_order(msg)
        ref = {"orderId": order.order_id, "orderUpdateId": str(order.update_id)}
        run = self.run
        if run is not None and order.order_id == run.order.order_id and run.order.order_id:
            self._update(run, order, ref)
            return
        if self.active and run is not None:
            self.agent.report(v.error("orderError", v.WARNING, f"order {run.order.order_id} "
                                      "is still running: cancel it first (cancelOrder)", ref))
            return
        why = check(order)
        if why:
            self.agent.report(v.error("orderError", v.WARNING, why, ref))
            return
        if not self.autonomy.connected:
            self.agent.report(v.error("orderError", v.WARNING, "the autonomy at "
                                      f"{self.autonomy.address} is not reachable "
                                      f"({self.autonomy.fault}); the order is refused", ref))
            return
        prefix = f"{order.order_id}:{order.update_id}"
        self.run = Running(order, plan_work(order, 0, prefix),
                           seq_at_receive=self.agent.status_seq)
        self.waiting_reason = "waiting for control to be free"
        self.agent.clear_order_errors()

    def _update(self, run: Running, order: v.Order, ref: dict[str, str]) -> None:
        old = run.order
        if order.update_id == old.update_id:
            return  # a repeat (VDA 5050: discard, keep running)
        if order.update_id < old.update_id:
            self.agent.report(v.error("orderUpdateError", v.WARNING, f"orderUpdateId "
                                      f"{order.update_id} is older than the one running "
                                      f"({old.update_id})", ref))
            return
        if run.closed:
            self.agent.report(v.error("orderUpdateError", v.WARNING, f"order {old.order_id} "
                                      "failed or was cancelled: send a new order", ref))
            return
        stitch = old.nodes[base_length(old) - 1]
        first = order.nodes[0]
        if (first.node_id, first.sequence_id) != (stitch.node_id, stitch.sequence_id):
            self.agent.report(v.error(
                "orderUpdateError", v.WARNING, f"the update must begin at the last base node "
                f"{stitch.node_id!r} (sequenceId {stitch.sequence_id}), not at "
                f"{first.node_id!r} ({first.sequence_id})", ref))
            return
        why = check(order)
        if not why and any(w.kind == RMC for w in run.work):
            why = "the order ends with rmcMission: it cannot be extended"
        if why:
            self.agent.report(v.error("orderUpdateError", v.WARNING, why, ref))
            return
        keep = base_length(old)
        nodes = [*old.nodes[:keep], *order.nodes[1:]]
        edges = [e for e in old.edges if e["sequenceId"] < stitch.sequence_id] + order.edges
        merged = v.Order(order.order_id, order.update_id, nodes, edges)
        prefix = f"{order.order_id}:{order.update_id}"
        run.order = merged
        run.work += plan_work(merged, keep, prefix)
        run.over = False
        self.agent.clear_order_errors()

    def tick(self, now: float) -> None:
        """Dispatch the next task when control allows; follow it to its end."""
        run = self.run
        if run is None or run.over:
            return
        work = run.current
        if work is None:
            run.over = True
            self.agent._state_due = True
            return
        st = self.autonomy.status
        status = self.agent.status
        owner = status.owner if status is not None else "unknown"
        if not run.dispatched:
            self._reach_without_driving(run, work)
            if self.agent.pause.paused:
                return
            if self.agent.status_seq < run.seq_at_receive + 2:
                return  # who holds control is known only from a poll sent after the order
            if owner not in ("none", mapping.AUTONOMY_OWNER):
                self.waiting_reason = f"waiting: {owner} holds control (an order never " \
                    "takes it)"
                return
            if not self.autonomy.connected:
                self.waiting_reason = f"waiting: the autonomy is not reachable " \
                    f"({self.autonomy.fault})"
                return
            self._dispatch(run, work)
            return
        if work.status not in (v.RUNNING, v.INITIALIZING) or not st:
            return
        if work.kind == RMC:
            self._follow_mission(run, work, st, owner)
            return
        task = st.get("task") or {}
        if task.get("id") != work.task_id:
            return  # a status from before the task began
        state, reason = task.get("state"), str(task.get("reason") or "")
        if work.kind == DUMP and task.get("step") in ("deposit", "decouple"):
            self._reached(run, work.node)  # docked: the collector node is reached
        if state == "done":
            self._finish(run, work, v.FINISHED, reason)
        elif state in ("failed", "cancelled"):
            self._fail(run, work, reason or state)
        elif state == "waiting":
            work.result = reason
        elif state == "held":
            work.result = f"paused: {reason}"
        else:
            work.result = f"{task.get('step')}: {reason}" if task.get("step") else reason

    def _reach_without_driving(self, run: Running, work: Work) -> None:
        """A node with no position (the robot's place) is reached where it stands."""
        n = _node(run, work)
        if n is not None and work.kind != GOTO and (n.x is None or n.y is None):
            self._reached(run, work.node)

    def _dispatch(self, run: Running, work: Work) -> None:
        run.dispatched = True
        self.waiting_reason = ""
        work.status = v.INITIALIZING
        n = _node(run, work)
        if work.kind == GOTO and n is not None:
            work.result = f"to node {n.node_id} at x {n.x:g} y {n.y:g}"
            args: dict[str, Any] = {"x": n.x, "y": n.y, "id": work.task_id}
            if n.theta is not None:
                args["theta"] = n.theta
            self.autonomy.command(GOTO, self._answer(run, work), **args)
        elif work.kind == DIG:
            assert work.action is not None
            work.result = "starting to dig"
            seconds = work.action.parameters.get("seconds")
            self.autonomy.command(DIG, self._answer(run, work), id=work.task_id,
                                  **({"seconds": seconds} if seconds is not None else {}))
        elif work.kind == DUMP:
            work.result = "to the collector"
            self.autonomy.command(DUMP, self._answer(run, work), id=work.task_id)
        else:
            work.result = "starting the mission"
            self.autonomy.command(RMC, self._answer(run, work))
        self.agent._state_due = True

    def _answer(self, run: Running, work: Work) -> Any:
        def answered(reply: dict[str, Any]) -> None:
            if self.run is not run or work.status != v.INITIALIZING:
                return
            if reply.get("ok"):
                work.status = v.RUNNING
                work.result = "the mission runs" if work.kind == RMC else \
                    work.result or "running"
            else:
                self._fail(run, work, f"the autonomy refused: {reply.get('error', 'no reason')}")
            self.agent._state_due = True
        return answered

    def _follow_mission(self, run: Running, work: Work, st: dict[str, Any],
                        owner: str) -> None:
        if owner not in ("none", mapping.AUTONOMY_OWNER) and work.status == v.RUNNING:
            work.result = f"paused: {owner} holds control; the mission resumes when control " \
                          "is free"
        elif work.result.startswith("paused: ") and owner in ("none", mapping.AUTONOMY_OWNER):
            work.result = "the mission runs"
        if st.get("over"):
            self._finish(run, work, v.FINISHED, f"mission {st.get('outcome')}: "
                         f"{st.get('delivered_kg', 0)} kg delivered")

    def _reached(self, run: Running, node: int) -> None:
        if node > run.reached:
            run.reached = node
            self.agent._state_due = True

    def _finish(self, run: Running, work: Work, status: str, result: str) -> None:
        work.status, work.result = status, result
        n = _node(run, work)
        if n is not None and (work.kind in (GOTO, DUMP) or n.x is None):
            self._reached(run, work.node)
        run.index += 1
        run.dispatched = False
        if run.index >= len(run.work):
            run.over = True
        self.agent._state_due = True

    def _fail(self, run: Running, work: Work, reason: str) -> None:
        """The work failed: the order stops; what is left is not run."""
        n = _node(run, work)
        node_id = n.node_id if n is not None else "(none)"
        work.status, work.result = v.FAILED, reason
        ref = {"orderId": run.order.order_id, "nodeId": node_id}
        if work.kind == GOTO:
            run.failure = v.error("noRouteError", v.WARNING, f"node {node_id} not reached: "
                                  f"{reason}", ref)
        else:
            run.failure = v.error("orderError", v.WARNING, f"action {work.kind} at node "
                                  f"{node_id} failed: {reason}; the order stopped", ref)
        for later in run.work[run.index + 1:]:
            later.status, later.result = v.FAILED, f"not run: {work.kind} at node " \
                f"{node_id} failed"
        run.over = run.closed = True
        run.dispatched = False
        self.agent._state_due = True

    def instant(self, action: v.Action) -> None:
        """`rmcMission` as an instant action: the same mission, with no order around it."""
        if self.active:
            self.agent._set_action(action, v.FAILED, "an order or mission is already running: "
                                   "cancel it first (cancelOrder)")
            return
        if not self.autonomy.connected:
            self.agent._set_action(action, v.FAILED, f"the autonomy at {self.autonomy.address} "
                                   f"is not reachable ({self.autonomy.fault})")
            return
        self.agent.actions.pop(action.action_id, None)  # reported below, as the order's
        self.run = Running(v.Order("", 0, [], []), [Work(RMC, -1, action)],
                           seq_at_receive=self.agent.status_seq)
        self.waiting_reason = "waiting for control to be free"

    def on_pause(self) -> None:
        """The fleet paused the robot: the autonomy holds (the agent sent it `pause`)."""
        if self.active and self.run is not None and self.run.current is not None:
            self.run.current.result = "paused by the fleet (stopPause)"

    def cancel(self) -> tuple[bool, str]:
        run = self.run
        if not self.active or run is None:
            return False, "no order to cancel"
        reason = f"order {run.order.order_id} cancelled"
        work = run.current
        if work is not None and work.kind == RMC and run.dispatched:
            self.autonomy.command("pause", reason=reason)
            told = "the mission is held where it is"
        else:
            self.autonomy.command("cancel", reason=reason)
            told = "the robot stops where it is"
        for w in run.work[run.index:]:
            w.status, w.result = v.FAILED, "cancelled by cancelOrder"
        run.over = run.closed = True
        run.dispatched = False
        self.agent._state_due = True
        return True, f"{reason}: {told}"

    # -- state --------------------------------------------------------------------------------
    def fill(self, f: v.StateFields) -> None:
        st = self.autonomy.status
        pose = st.get("pose") if st else None
        if st:
            score = float(st.get("confidence", 0.0))
            if isinstance(pose, dict):
                f.agv_position = v.position(pose["x"], pose["y"], pose["yaw"], score=score)
            f.information.append(v.info(
                "missionState", f"mission {st.get('state')}"
                + (f" (held: {st['held']})" if st.get("held") else ""),
                {"state": str(st.get("state")), "outcome": str(st.get("outcome")),
                 "deliveredKg": str(st.get("delivered_kg")), "binKg": str(st.get("bin_kg")),
                 "localizationScore": str(st.get("confidence"))}))
            task = st.get("task")
            if isinstance(task, dict):
                f.information.append(v.info(
                    "nodeTask", f"{task.get('kind')} {task.get('state')}: "
                    f"{task.get('step')} ({task.get('reason')})",
                    {"kind": str(task.get("kind")), "id": str(task.get("id")),
                     "state": str(task.get("state")), "step": str(task.get("step"))}))
        else:
            f.errors.append(v.error("autonomyUnreachable", v.WARNING, "the autonomy at "
                                    f"{self.autonomy.address} does not answer "
                                    f"({self.autonomy.fault}): orders cannot run"))
        run = self.run
        if run is None:
            return
        order = run.order
        f.order_id, f.order_update_id = order.order_id, order.update_id
        if run.reached >= 0 and order.nodes:
            last = order.nodes[min(run.reached, len(order.nodes) - 1)]
            f.last_node_id, f.last_node_sequence_id = last.node_id, last.sequence_id
        if not run.closed:  # what is left to traverse: the horizon too, once the base is done
            f.node_states = [v.node_state(n.raw) for n in order.nodes[run.reached + 1:]]
            f.edge_states = [v.edge_state(e) for e in order.edges
                             if e["sequenceId"] > f.last_node_sequence_id or run.reached < 0]
        if not run.over:
            if not run.dispatched and self.waiting_reason.startswith("waiting"):
                f.information.append(v.info("orderWaiting", self.waiting_reason))
            work = run.current
            if work is not None and work.status == v.RUNNING and \
                    work.result.startswith(("waiting", "paused: ")):
                f.information.append(v.info("orderWaiting", work.result))
        if run.failure is not None:
            f.errors.append(run.failure)
        f.action_states = [*f.action_states, *(
            v.action_state(w.action.action_id, w.kind, w.status, w.result)
            for w in run.work if w.action is not None)]
