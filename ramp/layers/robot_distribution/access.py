"""What each role may ask (SPEC 13), by the kind of request (`Function.kind`).

observer: reads, `describe`, heartbeats and every stop (a stop is accepted from every
authenticated client, always); operator: also motion, state (LEDs, its own watchdog
timeout, resets) and control; admin: also the simulator's `sim` module (a module outside
the registry: it acts on the world, not on the robot).
"""

from __future__ import annotations

from ramp.common.access import RANK

#: The weakest role that may send a request of each kind.
NEEDS = {"read": "observer", "stop": "observer", "motion": "operator", "state": "operator",
         "control": "operator"}


def forbidden(role: str, kind: str, world: bool) -> str | None:
    """Why `role` may not send a request of `kind` (to the simulated world's module when
    `world`), or None when it may."""
    need = "admin" if world and kind != "read" else NEEDS.get(kind, "operator")
    if RANK.get(role, 0) >= RANK[need]:
        return None
    return f"{role} may not send this request; it needs the {need} role"
