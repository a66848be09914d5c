"""The MARTE physics model, stepped in virtual time."""

from __future__ import annotations

import math

import pytest

from firmware_like.marte import (
    ANALOG_INPUTS,
    BRIDGE_INPUTS,
    DIGITAL_INPUTS,
    DIGITAL_OUTPUTS,
    MOTORS,
    WHEELS,
    MarteWorld,
)
from firmware_like.marte_params import MarteParams

DT = 0.01
LEFT = ("base.lf_wheel", "base.lb_wheel")
RIGHT = ("base.rf_wheel", "base.rb_wheel")


def run(world: MarteWorld, seconds: float, dt: float = DT) -> None:
    for _ in range(round(seconds / dt)):
        world.step(dt)


def drive(world: MarteWorld, left: float, right: float) -> None:
    """Raw duties per side, as the controllers see them (no polarity compensation)."""
    for name in LEFT:
        world.set_motor(name, left)
    for name in RIGHT:
        world.set_motor(name, right)


def forward(world: MarteWorld, duty: float = 1.0) -> None:
    """What the YAML's polarity makes of "forward": right side mirrored."""
    drive(world, duty, -duty)


def dig_chain(world: MarteWorld, duty: float = 1.0) -> None:
    world.set_motor("ble.chain_left", duty)
    world.set_motor("ble.chain_right", -duty)


def rear_at_wall(world: MarteWorld, y: float = 1.94) -> None:
    world.place(world.params.robot_length / 2, y, 0.0)


def in_dig_region(world: MarteWorld) -> None:
    world.place(6.0, 1.94, 0.0)


# ---- chassis ---------------------------------------------------------------------------------


def test_forward_two_seconds_moves_plausible_distance_straight() -> None:
    w = MarteWorld()
    x0, y0 = w.x, w.y
    forward(w)
    run(w, 2.0)
    # ~0.29 m/s top speed minus the 0.15 s lag: about 0.53 m.
    assert 0.4 < w.x - x0 < 0.65
    assert w.y == pytest.approx(y0, abs=1e-9)
    assert w.heading_deg == pytest.approx(0.0, abs=1e-9)
    for name in WHEELS:
        assert 0.25 < w.wheel_speed(name) < 0.33


def test_right_wheels_are_mirrored() -> None:
    w = MarteWorld()
    drive(w, 1.0, 1.0)
    run(w, 1.0)
    assert w.wheel_speed("base.lf_wheel") > 0.2
    assert w.wheel_speed("base.lb_wheel") > 0.2
    assert w.wheel_speed("base.rf_wheel") < -0.2
    assert w.wheel_speed("base.rb_wheel") < -0.2


def test_backward_and_heading_frame() -> None:
    w = MarteWorld()
    w.place(3.0, 1.94, 90.0)  # yaw 90 faces +y, the left side of the arena
    forward(w)
    run(w, 1.0)
    assert w.y > 1.94 + 0.15
    assert w.x == pytest.approx(3.0, abs=1e-9)
    forward(w, -1.0)
    run(w, 3.0)
    assert w.y < 1.94


def test_spin_in_place_clockwise_and_counter_clockwise() -> None:
    w = MarteWorld()
    w.place(3.0, 1.94, 0.0)
    drive(w, 1.0, 1.0)  # left forward, right backward: turn right = clockwise = - yaw
    run(w, 1.0)
    assert w.heading_deg < -15.0
    assert math.hypot(w.x - 3.0, w.y - 1.94) < 1e-9
    h = w.heading_deg
    drive(w, -1.0, -1.0)
    run(w, 2.0)
    assert w.heading_deg > h + 15.0
    assert math.hypot(w.x - 3.0, w.y - 1.94) < 1e-9


def test_turning_right_while_driving_curves_toward_minus_y() -> None:
    w = MarteWorld()
    w.place(3.0, 1.94, 0.0)
    drive(w, 1.0, -0.5)  # left faster than right
    run(w, 2.0)
    assert w.heading_deg < -5.0
    assert w.y < 1.94


def test_turning_left_increases_yaw_and_curves_toward_plus_y() -> None:
    """SPEC 6.1's frame: +y on the left facing +x, yaw counter-clockwise."""
    w = MarteWorld()
    w.place(3.0, 1.94, 0.0)
    drive(w, 0.5, -1.0)  # right faster than left
    run(w, 2.0)
    assert w.heading_deg > 5.0
    assert w.y > 1.94
    assert w.imu_truth().angular_velocity[2] > 0.0


def test_walls_clamp_every_side() -> None:
    p = MarteParams()
    w = MarteWorld()
    forward(w, -1.0)
    run(w, 5.0)
    assert w.rear_x() == pytest.approx(0.0, abs=1e-9)
    assert w.x == pytest.approx(p.robot_length / 2, abs=1e-9)
    w.place(6.0, 1.94, 0.0)
    forward(w)
    run(w, 8.0)
    assert w.front_x() == pytest.approx(p.arena_length, abs=1e-9)
    w.place(3.0, 1.94, 90.0)
    run(w, 10.0)
    assert w.y == pytest.approx(p.arena_width - p.robot_length / 2, abs=1e-9)
    w.place(3.0, 1.94, -90.0)
    run(w, 10.0)
    assert w.y == pytest.approx(p.robot_length / 2, abs=1e-9)


def test_place_rejects_poses_outside_the_arena() -> None:
    w = MarteWorld()
    with pytest.raises(ValueError, match="outside"):
        w.place(0.2, 1.94, 0.0)
    assert w.x == pytest.approx(0.85)  # unchanged after a refused place


def test_regions_of_the_centre() -> None:
    w = MarteWorld()
    assert w.region() == "start"
    w.place(3.0, 1.94, 0.0)
    assert w.region() == "obstacle"
    w.place(5.0, 1.94, 0.0)
    assert w.region() == "dig"


# ---- docking buttons ---------------------------------------------------------------------------


def test_buttons_close_when_backing_into_the_wall() -> None:
    w = MarteWorld()
    assert not w.read_digital("base.l_button")
    assert not w.read_digital("base.r_button")
    forward(w, -0.5)
    run(w, 4.0)
    assert w.read_digital("base.l_button")
    assert w.read_digital("base.r_button")
    forward(w, 1.0)
    run(w, 1.0)
    assert not w.read_digital("base.l_button")
    assert not w.read_digital("base.r_button")


def test_one_button_when_angled() -> None:
    w = MarteWorld()
    h = math.radians(5.0)  # nose turned right (clockwise): the rear-right corner is nearer
    x = 0.6 * math.cos(h) + 0.375 * math.sin(h) + 0.005
    w.place(x, 1.94, -5.0)
    assert w.read_digital("base.r_button")
    assert not w.read_digital("base.l_button")
    w.place(x, 1.94, 5.0)
    assert w.read_digital("base.l_button")
    assert not w.read_digital("base.r_button")


def test_buttons_only_at_the_collector_wall() -> None:
    w = MarteWorld()
    w.place(6.78, 1.94, 180.0)  # rear against the far wall, not the collector wall
    assert not w.read_digital("base.l_button")
    assert not w.read_digital("base.r_button")


# ---- battery -------------------------------------------------------------------------------------


def test_battery_sags_under_load_and_recovers() -> None:
    w = MarteWorld()
    run(w, 0.5)
    rest = w.battery_voltage
    assert 20.5 < rest <= 21.0
    forward(w)
    run(w, 1.0)
    loaded = w.battery_voltage
    assert rest - loaded > 0.3
    forward(w, 0.0)
    run(w, 0.5)
    assert w.battery_voltage - loaded > 0.3
    assert w.battery_voltage == pytest.approx(rest, abs=0.05)


def test_battery_sensor_volts_follow_phidget_1135_conversion() -> None:
    w = MarteWorld()
    forward(w)
    for _ in range(50):
        w.step(DT)
        vout = w.read_analog("base.battery")
        assert abs(vout - (2.5 + 0.0681 * w.battery_voltage)) < 0.005
        assert (vout - 2.5) / 0.0681 == pytest.approx(w.battery_voltage, abs=0.08)


def test_soc_decreases_faster_under_load() -> None:
    idle, busy = MarteWorld(), MarteWorld()
    forward(busy)
    run(idle, 10.0)
    run(busy, 10.0)
    assert idle.battery_soc < 1.0
    assert busy.battery_soc < idle.battery_soc
    # 61.5 A for ~10 s out of 10 Ah is ~1.7 % of charge.
    assert 1.0 - busy.battery_soc == pytest.approx(61.5 * 10 / 36000, rel=0.05)


def test_low_battery_is_slower_and_lower() -> None:
    full, empty = MarteWorld(), MarteWorld(MarteParams(initial_soc=0.0))
    for w in (full, empty):
        forward(w)
        run(w, 2.0)
    assert empty.battery_voltage < 17.0
    assert full.battery_voltage > 18.5
    assert empty.x < full.x - 0.05


def test_digging_adds_load_current() -> None:
    free, digging = MarteWorld(), MarteWorld()
    in_dig_region(digging)
    for w in (free, digging):
        dig_chain(w)
        run(w, 1.0)
    assert digging.digging and not free.digging
    assert digging.battery_current > free.battery_current + 5.0


# ---- lift ----------------------------------------------------------------------------------------


def test_lift_full_stroke_about_ten_seconds_and_stops_at_ends() -> None:
    w = MarteWorld()
    w.set_motor("ble.lift_motor", 1.0)
    while w.lift_pos < 1.0 and w.time < 20.0:
        w.step(DT)
    assert 9.0 < w.time < 11.0
    run(w, 2.0)
    assert w.lift_pos == 1.0
    t0 = w.time
    w.set_motor("ble.lift_motor", -1.0)
    while w.lift_pos > 0.0 and w.time < t0 + 20.0:
        w.step(DT)
    assert 9.0 < w.time - t0 < 11.0
    run(w, 2.0)
    assert w.lift_pos == 0.0


def test_lift_half_duty_half_speed() -> None:
    w = MarteWorld()
    w.set_motor("ble.lift_motor", 0.5)
    run(w, 4.0)
    assert 0.17 < w.lift_pos < 0.22


def test_pot_volts_track_position() -> None:
    w = MarteWorld()
    assert w.read_analog("ble.lift_pot") == pytest.approx(0.6, abs=0.005)
    w.set_motor("ble.lift_motor", 1.0)
    for _ in range(1200):
        w.step(DT)
        expected = 0.6 + 3.8 * w.lift_pos
        assert abs(w.read_analog("ble.lift_pot") - expected) < 0.005
    assert w.read_analog("ble.lift_pot") == pytest.approx(4.4, abs=0.005)


def test_jammed_lift_stalls_and_draws_more_current() -> None:
    free, jammed = MarteWorld(), MarteWorld()
    jammed.jam_lift(True)
    for w in (free, jammed):
        w.set_motor("ble.lift_motor", 1.0)
        run(w, 2.0)
    assert jammed.lift_pos == 0.0
    assert free.lift_pos > 0.15
    assert jammed.battery_current > free.battery_current + 5.0
    jammed.jam_lift(False)
    run(jammed, 1.0)
    assert jammed.lift_pos > 0.05


def test_lift_jam_holds_mid_stroke() -> None:
    w = MarteWorld()
    w.set_motor("ble.lift_motor", 1.0)
    run(w, 3.0)
    pos = w.lift_pos
    w.jam_lift(True)
    run(w, 3.0)
    assert w.lift_pos == pos
    w.set_motor("ble.lift_motor", -1.0)
    run(w, 1.0)
    assert w.lift_pos == pos


# ---- digging --------------------------------------------------------------------------------


def test_digs_in_dig_region_with_ladder_down_and_chain_digging() -> None:
    w = MarteWorld()
    in_dig_region(w)
    dig_chain(w)
    run(w, 10.0)
    # ~0.3 kg/s at full chain speed, less the spin-up.
    assert 2.7 < w.bin_kg < 3.3
    assert w.excavated_kg == pytest.approx(w.bin_kg)


def test_front_in_dig_region_is_enough() -> None:
    w = MarteWorld()
    w.place(4.44 - 0.5, 1.94, 0.0)  # centre in the obstacle region, front 0.1 m into dig
    assert w.region() == "obstacle"
    dig_chain(w)
    run(w, 2.0)
    assert w.bin_kg > 0.3
    w2 = MarteWorld()
    w2.place(4.44 - 0.7, 1.94, 0.0)  # front 0.1 m short
    dig_chain(w2)
    run(w2, 2.0)
    assert w2.bin_kg == 0.0


@pytest.mark.parametrize(
    ("where", "left", "right", "lift_up"),
    [
        ("start", 1.0, -1.0, False),  # wrong region
        ("dig", -1.0, 1.0, False),  # chain runs backwards
        ("dig", 1.0, 1.0, False),  # the two motors fight: belt does not move
        ("dig", 1.0, -1.0, True),  # ladder lifted out of the soil
    ],
)
def test_no_digging_unless_all_conditions(where: str, left: float, right: float,
                                          lift_up: bool) -> None:
    w = MarteWorld()
    if where == "dig":
        in_dig_region(w)
    if lift_up:
        w.lift_pos = 0.2
    w.set_motor("ble.chain_left", left)
    w.set_motor("ble.chain_right", right)
    run(w, 3.0)
    assert w.bin_kg == 0.0


def test_bin_stops_at_capacity() -> None:
    w = MarteWorld(MarteParams(bin_capacity=1.0))
    in_dig_region(w)
    dig_chain(w)
    run(w, 10.0)
    assert w.bin_kg == pytest.approx(1.0)
    assert not w.digging


def test_load_cell_tracks_bin_mass() -> None:
    w = MarteWorld()
    assert w.read_bridge("ble.load_cell") == pytest.approx(0.25, abs=0.001)
    for kg in (0.0, 5.0, 12.5, 40.0):
        w.bin_kg = kg
        w.step(DT)
        assert abs(w.read_bridge("ble.load_cell") - (0.25 + 0.02 * kg)) < 0.001
    in_dig_region(w)
    w.bin_kg = 0.0
    dig_chain(w)
    run(w, 5.0)
    assert w.bin_kg > 1.0
    assert abs((w.read_bridge("ble.load_cell") - 0.25) / 0.02 - w.bin_kg) < 0.05


# ---- dumping --------------------------------------------------------------------------------


def test_dump_over_collector_delivers() -> None:
    w = MarteWorld()
    rear_at_wall(w)
    assert w.at_collector()
    w.bin_kg = 10.0
    w.lift_pos = 0.9
    run(w, 2.0)
    assert 0.0 < w.bin_kg < 10.0  # a steady rate, not all at once
    run(w, 10.0)
    assert w.bin_kg == 0.0
    assert w.delivered_kg == pytest.approx(10.0)
    assert w.spilled_kg == 0.0


@pytest.mark.parametrize(("x", "y", "heading"), [
    (3.0, 1.94, 0.0),  # middle of the arena
    (0.6, 0.40, 0.0),  # at the wall but beside the collector
    (0.8, 1.94, 0.0),  # 0.2 m short of the wall
    (0.76, 1.94, 0.0),  # 0.16 m short: just beyond SPEC 6.1's 0.15 m
    (0.6, 1.94 - 0.5, 0.0),  # rear half outside the collector's width (it spans 1.115..2.765)
    (1.5, 1.94, 180.0),  # facing the wall: the rear is away from it
])
def test_dump_elsewhere_spills(x: float, y: float, heading: float) -> None:
    w = MarteWorld()
    w.place(x, y, heading)
    assert not w.at_collector()
    w.bin_kg = 6.0
    w.lift_pos = 0.95
    run(w, 5.0)
    assert w.spilled_kg == pytest.approx(6.0)
    assert w.delivered_kg == 0.0


def test_no_dump_below_threshold_and_lifting_starts_it() -> None:
    w = MarteWorld()
    rear_at_wall(w)
    w.bin_kg = 8.0
    w.lift_pos = 0.5
    run(w, 3.0)
    assert w.bin_kg == 8.0
    w.set_motor("ble.lift_motor", 1.0)
    run(w, 10.0)
    assert w.delivered_kg > 4.0
    assert w.delivered_kg + w.bin_kg == pytest.approx(8.0)


def test_dig_then_drive_home_and_deliver() -> None:
    """A compressed mission, all through motor commands."""
    w = MarteWorld()
    w.place(5.5, 1.94, 0.0)
    dig_chain(w)
    run(w, 20.0)
    dig_chain(w, 0.0)
    forward(w, -1.0)
    run(w, 25.0)  # backs all the way to the collector wall
    assert w.read_digital("base.l_button") and w.read_digital("base.r_button")
    dug = w.bin_kg  # includes what the chain scooped while spinning down
    assert dug > 5.0
    forward(w, 0.0)
    w.set_motor("ble.lift_motor", 1.0)
    run(w, 15.0)
    assert w.delivered_kg == pytest.approx(dug)
    assert w.spilled_kg == 0.0


# ---- signals, determinism, integration -------------------------------------------------------


def test_leds_read_back() -> None:
    w = MarteWorld()
    for name in DIGITAL_OUTPUTS:
        assert w.output(name) is False
        w.write_digital(name, True)
        assert w.output(name) is True
    w.write_digital("base.led_mid", False)
    assert w.output("base.led_mid") is False
    assert w.output("base.led_high") is True


@pytest.mark.parametrize("call", [
    lambda w: w.set_motor("base.lf_wheeel", 0.5),
    lambda w: w.read_analog("base.batery"),
    lambda w: w.read_digital("base.user_led"),
    lambda w: w.write_digital("base.l_button", True),
    lambda w: w.read_bridge("ble.load"),
    lambda w: w.wheel_speed("ble.chain_left"),
])
def test_unknown_names_raise_key_error_listing_known(call: object) -> None:
    w = MarteWorld()
    with pytest.raises(KeyError, match="known: "):
        call(w)  # type: ignore[operator]


def test_signal_names_are_exactly_the_yaml_devices() -> None:
    assert set(MOTORS) == {"base.lf_wheel", "base.lb_wheel", "base.rf_wheel", "base.rb_wheel",
                           "ble.chain_left", "ble.chain_right", "ble.lift_motor"}
    assert set(ANALOG_INPUTS) == {"base.battery", "ble.lift_pot"}
    assert set(DIGITAL_INPUTS) == {"base.l_button", "base.r_button"}
    assert set(BRIDGE_INPUTS) == {"ble.load_cell"}


def test_duty_is_clamped_and_must_be_finite() -> None:
    w = MarteWorld()
    w.set_motor("ble.lift_motor", 3.0)
    assert w.duty("ble.lift_motor") == 1.0
    w.set_motor("ble.lift_motor", -3.0)
    assert w.duty("ble.lift_motor") == -1.0
    with pytest.raises(ValueError):
        w.set_motor("ble.lift_motor", math.nan)
    with pytest.raises(ValueError):
        w.step(-0.01)


def script(w: MarteWorld) -> list[float]:
    """A fixed command script; returns every reading taken along the way."""
    out: list[float] = []
    w.place(4.0, 1.5, 10.0)
    drive(w, 0.8, -0.6)
    w.set_motor("ble.lift_motor", -0.3)
    dig_chain(w, 0.9)
    for _ in range(300):
        w.step(DT)
        out += [w.read_analog("base.battery"), w.read_analog("ble.lift_pot"),
                w.read_bridge("ble.load_cell")]
    out += [w.x, w.y, w.heading, w.bin_kg, w.battery_soc, w.battery_voltage]
    return out


def test_same_seed_same_results_other_seed_other_noise() -> None:
    a, b, c = MarteWorld(seed=7), MarteWorld(seed=7), MarteWorld(seed=8)
    ra, rb, rc = script(a), script(b), script(c)
    assert ra == rb
    assert ra != rc
    assert ra[-6:] == rc[-6:]  # the noise is only on the sensors


def test_repeated_reads_between_steps_agree() -> None:
    w = MarteWorld()
    w.step(DT)
    assert w.read_analog("base.battery") == w.read_analog("base.battery")
    assert w.read_bridge("ble.load_cell") == w.read_bridge("ble.load_cell")


def test_large_steps_are_stable_and_agree_with_small_ones() -> None:
    fine, coarse, huge = MarteWorld(), MarteWorld(), MarteWorld()
    for w in (fine, coarse, huge):
        w.place(3.0, 1.94, 0.0)
        drive(w, 1.0, -0.3)
        w.set_motor("ble.lift_motor", 1.0)
    run(fine, 4.0, 0.01)
    run(coarse, 4.0, 0.05)
    huge.step(4.0)  # split into 0.05 s pieces internally
    for w in (coarse, huge):
        assert w.x == pytest.approx(fine.x, abs=0.02)
        assert w.y == pytest.approx(fine.y, abs=0.02)
        assert w.heading_deg == pytest.approx(fine.heading_deg, abs=1.0)
        assert w.lift_pos == pytest.approx(fine.lift_pos, abs=0.01)
        assert w.time == pytest.approx(4.0)
    assert coarse.x == pytest.approx(huge.x, abs=1e-9)


def test_unplug_and_replug() -> None:
    w = MarteWorld()
    assert w.bus_present("base_motors")
    w.unplug("base_motors")
    assert not w.bus_present("base_motors")
    assert w.bus_present("ble_motors")
    w.replug("base_motors")
    assert w.bus_present("base_motors")


def test_time_advances() -> None:
    w = MarteWorld()
    run(w, 1.5)
    assert w.time == pytest.approx(1.5)
    w.step(0.0)
    assert w.time == pytest.approx(1.5)


def test_drives_through_the_sim_driver() -> None:
    """The world satisfies ramp.hal.simio's SimWorld: channels by label, unplug -> fault."""
    from ramp.errors import DeviceError
    from ramp.hal.simio import SimBus

    w = MarteWorld()
    bus = SimBus("base_io", {}, world=w)
    lf = bus.channel("motor", "base.lf_wheel", {})
    battery = bus.channel("analog_in", "base.battery", {})
    button = bus.channel("digital_in", "base.l_button", {})
    led = bus.channel("digital_out", "base.user_led", {})
    load = bus.channel("bridge_in", "ble.load_cell", {})
    bus.open(0.0)
    lf.set_duty(0.5)
    led.write(True)
    run(w, 1.0)
    bus.tick(1.0, 0.01)  # inputs are sampled in the bus's tick, as a real board's arrive
    assert w.duty("base.lf_wheel") == 0.5
    assert w.wheel_speed("base.lf_wheel") > 0.1
    assert w.output("base.user_led") is True
    assert battery.read() == pytest.approx(2.5 + 0.0681 * w.battery_voltage, abs=0.005)
    assert button.read() is False
    assert load.read() == pytest.approx(0.25, abs=0.001)
    w.unplug("base_io")
    with pytest.raises(DeviceError):
        bus.tick(1.0, 0.01)
    bus.stop_motors()
    assert w.duty("base.lf_wheel") == 0.0
    w.replug("base_io")
    bus.tick(1.0, 0.01)
    bus.close()
