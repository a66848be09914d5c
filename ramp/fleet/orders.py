"""Orders for a robot with the autonomy (SPEC 14), run through the autonomy's command
endpoint (ramp/autonomy/command.py; the design is in docs/operating/fleet.md).

What runs today: an order whose node carries the `rmcMission` action: the whole RMC mission,
driven by the autonomy's own planner and localizer. The node is the robot's place when the
mission starts (its position, if given, is reported back, not driven to). Orders with more
than one node, and `dig`/`dump` actions, are refused with an `orderError` that says so: the
autonomy has no node-by-node mode yet.

Safety: the order is sent to the autonomy only while nobody else holds control (control free
or the autonomy's): under an operator it waits, and `state` says so; a fleet pause refuses
orders; `cancelOrder` holds the mission (it stops where it is).
"""

from __future__ import annotations

from typing import Any

from ramp.fleet import mapping
from ramp.fleet import vda5050 as v

RMC = "rmcMission"


class Orders:
    """The order the robot runs (one at a time), and its states for `state`."""

    def __init__(self, agent: Any, autonomy: Any) -> None:
        self.agent = agent
        self.autonomy = autonomy
        self.order: v.Order | None = None
        self.action: v.Action | None = None
        self.action_status = v.WAITING
        self.result = ""
        self.dispatched = False
        self.last_node_id = ""
        self.last_node_seq = 0
        self.waiting_reason = ""
        self._seq_at_receive = 0

    # -- what the agent asks ------------------------------------------------------------------
    @property
    def active(self) -> bool:
        """An order is in hand (waiting or running)."""
        return self.order is not None and self.action_status in (v.WAITING, v.INITIALIZING,
                                                                 v.RUNNING)

    @property
    def running(self) -> bool:
        """The fleet's order is driving the robot (SEMIAUTOMATIC)."""
        st = self.autonomy.status
        return self.active and self.dispatched and bool(st) and not st.get("held") \
            and not st.get("over")

    def factsheet_actions(self) -> list[dict[str, Any]]:
        return [v.agv_action(RMC, "the whole RMC mission (dig, return, deposit, until the "
                             "run's time is nearly out), by the autonomy's own planner and "
                             "localizer, from where the robot stands", ["INSTANT", "NODE"],
                             result="delivered kg")]

    # -- orders -------------------------------------------------------------------------------
    def receive(self, msg: dict[str, Any]) -> None:
        order = v.parse_order(msg)
        ref = {"orderId": order.order_id, "orderUpdateId": str(order.update_id)}
        if self.order is not None and order.order_id == self.order.order_id:
            if order.update_id <= self.order.update_id:
                return  # a repeat (VDA 5050: discard, keep running)
            self.agent.report(v.error("orderUpdateError", v.WARNING, "order updates are not "
                                      "supported: cancel the order and send a new one", ref))
            return
        if self.active and self.order is not None:
            self.agent.report(v.error("orderError", v.WARNING, f"order {self.order.order_id} "
                                      "is still running: cancel it first (cancelOrder)", ref))
            return
        why = self._unsupported(order)
        if why:
            self.agent.report(v.error("orderError", v.WARNING, why, ref))
            return
        if not self.autonomy.connected:
            self.agent.report(v.error("orderError", v.WARNING, "the autonomy at "
                                      f"{self.autonomy.address} is not reachable "
                                      f"({self.autonomy.fault}); the order is refused", ref))
            return
        self.order = order
        self._seq_at_receive = self.agent.status_seq
        node = order.nodes[0]
        self.action = node.actions[0]
        self.action_status, self.result = v.WAITING, "waiting for control to be free"
        self.dispatched = False
        self.agent.clear_order_errors()

    def _unsupported(self, order: v.Order) -> str:
        if len(order.nodes) != 1 or order.edges:
            return ("this robot's autonomy runs whole RMC missions only: send one node with "
                    "the rmcMission action (node-by-node driving is not implemented)")
        acts = order.nodes[0].actions
        if len(acts) != 1 or acts[0].action_type != RMC:
            kinds = ", ".join(a.action_type for a in acts) or "none"
            return (f"unsupported node actions ({kinds}): this robot runs one rmcMission "
                    "action per order (dig and dump alone are not implemented)")
        if not order.nodes[0].released:
            return "the node is not released (horizon only): nothing to do"
        return ""

    def tick(self, now: float) -> None:
        """Dispatch when control allows; follow the mission to its end."""
        if not self.active or self.order is None:
            return
        st = self.autonomy.status
        status = self.agent.status
        owner = status.owner if status is not None else "unknown"
        if not self.dispatched:
            if self.agent.pause.paused:
                return
            if self.agent.status_seq < self._seq_at_receive + 2:
                return  # who holds control is known only from a poll sent after the order
            if owner not in ("none", mapping.AUTONOMY_OWNER):
                self.result = f"waiting: {owner} holds control (an order never takes it)"
                return
            if not self.autonomy.connected:
                self.result = f"waiting: the autonomy is not reachable ({self.autonomy.fault})"
                return
            self.dispatched = True
            self.action_status, self.result = v.INITIALIZING, "starting the mission"
            self.autonomy.command(RMC, self._dispatched)
            return
        if owner not in ("none", mapping.AUTONOMY_OWNER) and self.action_status == v.RUNNING:
            self.result = f"paused: {owner} holds control; the mission resumes when control " \
                          "is free"
        elif self.result.startswith("paused: ") and owner in ("none", mapping.AUTONOMY_OWNER):
            self.result = "the mission runs"
        if st.get("over"):
            self.action_status = v.FINISHED
            self.result = f"mission {st.get('outcome')}: {st.get('delivered_kg', 0)} kg " \
                          "delivered"
            self._reached_first_node()

    def _dispatched(self, reply: dict[str, Any]) -> None:
        if self.order is None:
            return
        if reply.get("ok"):
            self.action_status, self.result = v.RUNNING, "the mission runs"
            self._reached_first_node()
        else:
            self.action_status = v.FAILED
            self.result = f"the autonomy refused: {reply.get('error', 'no reason')}"
        self.agent._state_due = True

    def _reached_first_node(self) -> None:
        if self.order is not None and self.order.nodes:
            self.last_node_id = self.order.nodes[0].node_id
            self.last_node_seq = self.order.nodes[0].sequence_id

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
        self.order = v.Order("", 0, [], [])
        self._seq_at_receive = self.agent.status_seq
        self.action = action
        self.action_status, self.result = v.WAITING, "waiting for control to be free"
        self.dispatched = False

    def on_pause(self) -> None:
        """The fleet paused the robot: the autonomy holds (the agent sent it `pause`)."""
        if self.active:
            self.result = "paused by the fleet (stopPause)"

    def cancel(self) -> tuple[bool, str]:
        if not self.active or self.order is None:
            return False, "no order to cancel"
        self.autonomy.command("pause", reason=f"order {self.order.order_id} cancelled")
        self.action_status, self.result = v.FAILED, "cancelled by cancelOrder"
        return True, f"order {self.order.order_id} cancelled: the mission is held where it is"

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
        else:
            f.errors.append(v.error("autonomyUnreachable", v.WARNING, "the autonomy at "
                                    f"{self.autonomy.address} does not answer "
                                    f"({self.autonomy.fault}): orders cannot run"))
        if self.order is None:
            return
        f.order_id, f.order_update_id = self.order.order_id, self.order.update_id
        f.last_node_id, f.last_node_sequence_id = self.last_node_id, self.last_node_seq
        if self.active:
            f.node_states = [v.node_state(n.raw) for n in self.order.nodes]
            if self.result.startswith(("waiting", "paused: ")):
                f.information.append(v.info("orderWaiting", self.result))
        if self.action is not None:
            f.action_states = [*f.action_states, v.action_state(
                self.action.action_id, RMC, self.action_status, self.result)]
