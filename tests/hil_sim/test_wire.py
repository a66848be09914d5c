"""MCP down to the bytes: the real Sabertooth driver against its emulator on a pty."""

from __future__ import annotations

import pytest

from tests.harness import SimHarness


@pytest.fixture
def h() -> SimHarness:
    harness = SimHarness()
    yield harness
    harness.close()


def base_emulator(h: SimHarness):  # type: ignore[no-untyped-def]
    return h.backplane.sabertooth["base_motors"].emulator


def test_commands_reach_the_controllers_as_valid_packets(h: SimHarness) -> None:
    c = h.connect()
    emu = base_emulator(h)
    assert c.ask("base:lf_wheel.vel=(50)base:rf_wheel.vel=(-100)") == ""
    h.advance(0.05)
    assert emu.duty(128, 1) == pytest.approx(64 / 127, abs=1e-6)  # + forward, 50 %
    assert emu.duty(129, 1) == pytest.approx(1.0)  # rf polarity -1: -100 % is +full
    assert emu.counters["bad_checksum"] == 0
    # the controller timeout was programmed (command 14, 0.5 s = 5 units) before motion
    cmds = [(a, cmd, d) for _, a, cmd, d in emu.packets]
    assert (128, 14, 5) in cmds and (129, 14, 5) in cmds
    first_motion = next(i for i, (a, cmd, d) in enumerate(cmds) if cmd in (0, 1) and d)
    assert cmds.index((128, 14, 5)) < first_motion


def test_a_flood_leaves_the_newest_value_within_two_ticks_under_the_baud_limit(
        h: SimHarness) -> None:
    c = h.connect()
    emu = base_emulator(h)
    h.advance(1.0)
    start = h.clock.now()
    # 3,000 requests in 30 messages within 0.3 s of simulated time, every wheel changing
    for burst in range(30):
        reqs = "".join(f"base:{w}.vel=({(burst * 7 + i) % 201 - 100})"
                       for i in range(25) for w in ("lf_wheel", "lb_wheel", "rf_wheel",
                                                    "rb_wheel"))
        assert c.ask(reqs) == ""
        h.advance(0.01)
    assert c.ask("base:lb_wheel.vel=(-12)base:lf_wheel.vel=(37)") == ""
    end_of_flood = h.clock.now()
    # 9600 baud carries 2.4 packets per 10 ms tick. Three channels are pending (lb first);
    # the newest value of the first is on the wire within two ticks, and of every channel
    # within three: no stale backlog sits in the OS buffer.
    h.advance(0.02)
    assert emu.duty(128, 2) == pytest.approx(-round(0.12 * 127) / 127, abs=1e-6)
    h.advance(0.01)
    assert emu.duty(128, 1) == pytest.approx(round(0.37 * 127) / 127, abs=1e-6)
    # bytes per sliding one-second window never above baud/10 = 960
    h.advance(1.0)
    times = [t for t, *_ in emu.packets if t >= start - 1.0]
    worst = max(sum(1 for u in times if t <= u < t + 1.0) for t in times) * 4
    assert worst <= 960
    assert end_of_flood - start < 0.4
    bus = h.sup.buses["base_motors"]
    assert bus.stats["max_pending"] <= 4  # one pending value per channel, no backlog


def test_closing_the_pty_faults_the_base_keeps_the_ble_and_reattaches(h: SimHarness) -> None:
    c = h.connect()
    device = h.backplane.sabertooth["base_motors"]
    assert c.ask("base:base.drive=(40,0)") == ""
    device.link.unplug()
    h.advance(0.05)
    get = c.ask("robot:robot.get=()")
    assert "robot:base.state=(fault)" in get and "robot:ble.state=(ok)" in get
    assert c.ask("base:base.drive=(40,0)").startswith("base:base.error=(fault,")
    assert c.ask("ble:chain.vel=(30)") == ""
    assert c.ask("robot:robot.modules=()") == "robot:robot.modules=(ble)"
    device.link.replug()
    h.advance(1.5)
    assert "robot:base.state=(ok)" in c.ask("robot:robot.get=()")
    assert c.ask("base:base.drive=(20,0)") == ""
    h.advance(0.05)
    assert device.emulator.duty(128, 1) > 0


def test_watchdog_trip_puts_zeros_on_the_wire(h: SimHarness) -> None:
    c = h.connect()
    emu = base_emulator(h)
    c.ask("base:base.drive=(80,0)")
    h.advance(0.1)
    assert emu.duty(128, 1) > 0.5
    h.advance(1.05)  # silent past the 1 s watchdog
    assert all(emu.duty(a, m) == 0.0 for a in (128, 129) for m in (1, 2))
    assert not any(emu.timed_out(a) for a in (128, 129))  # the supervisor stopped them


def test_moving_a_wheel_to_another_channel_is_a_yaml_edit() -> None:
    from tests.harness import MARTE_YAML

    swapped = (MARTE_YAML
               .replace("lf_wheel: {bus: base_motors, address: 128, motor: 1}",
                        "lf_wheel: {bus: base_motors, address: 128, motor: 2}")
               .replace("lb_wheel: {bus: base_motors, address: 128, motor: 2}",
                        "lb_wheel: {bus: base_motors, address: 128, motor: 1}"))
    assert swapped.count("motor: 2}") == MARTE_YAML.count("motor: 2}")
    h = SimHarness(swapped)
    try:
        c = h.connect()
        emu = base_emulator(h)
        assert c.ask("base:lf_wheel.vel=(50)") == ""
        h.advance(0.05)
        assert emu.duty(128, 2) == pytest.approx(64 / 127, abs=1e-6)  # the new channel
        assert emu.duty(128, 1) == 0.0
    finally:
        h.close()
