"""`ramp.runtime.service.serve`: what `ramp run` and the realtime mission's backend share."""

from __future__ import annotations

import gc

from ramp.clock import MonotonicClock
from ramp.runtime import build
from ramp.runtime.service import ServiceState, scheduling_priority, serve
from ramp.simulation.backend import load_backend_config
from ramp.simulation.backplane import RUN_PHYSICS_HZ, SimBackplane


def test_serve_runs_the_stall_guard_freezes_the_heap_and_stops_the_motors() -> None:
    config = load_backend_config()
    backplane = SimBackplane(config, physics_hz=RUN_PHYSICS_HZ, read_in_wait=False)
    sup = build(config, MonotonicClock(), backplane.bus_factory, host="127.0.0.1", port=0)
    backplane.attach(sup)
    seen: list[ServiceState] = []
    ticks = [0]

    def ready(state: ServiceState) -> None:
        seen.append(state)
        assert sup.stall_guard.running  # the guard watches while the loop runs

    def until() -> bool:
        ticks[0] += 1
        return ticks[0] > 5

    try:
        # No stop signals and no priority: this is the test runner's own process.
        code = serve(sup, ready=ready, until=until, stop_signals=(), on_stop=backplane.close)
    finally:
        gc.unfreeze()
    assert code == 0
    assert len(seen) == 1
    assert seen[0].stall_guard
    assert seen[0].gc_frozen > 0
    assert seen[0].policy.startswith(("default", "fifo", "rr"))
    assert not sup.stall_guard.running  # stopped with the loop
    assert not sup.running  # shut down: zeros on every wire


def test_no_priority_asked_leaves_the_process_as_it_is() -> None:
    assert scheduling_priority(None).startswith(("default", "fifo", "rr"))
