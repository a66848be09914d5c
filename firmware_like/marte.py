"""The MARTE physics model: the world the emulators and the sim driver move and read.

One object holds the arena, the skid-steer Base, its battery and the Bucket Ladder
Excavator. It is advanced only by `step(dt)`, which integrates every state from
differentials, so a run depends on nothing but the sequence of commands, the steps and the
seed. Device emulators (Sabertooth over a pty, ...) and the HAL-level `sim` driver address
its signals by the YAML names `module.device`; `ramp/` never imports this file except
through the one simulation entry point.

Frames and signs: the arena frame of SPEC 6.1, which the autonomy, traces and referee use.

- x runs along the arena's 7.38 m length, from the collector wall (x = 0) towards the
  digging region; y runs across its 3.88 m width, +y on the LEFT when facing +x; z is up.
- heading (yaw) 0 faces +x and grows COUNTER-CLOCKWISE seen from above, so heading 90 deg
  faces +y. A positive yaw rate is a turn to the left. SPEC 2.3's drive direction 90 spins
  the robot clockwise, so its yaw DECREASES. The body frame is x forward, y left, z up; roll,
  pitch and yaw are Z-Y-X Euler angles in it (pitch positive nose DOWN, roll positive left
  side UP: right-handed about y-left and x-forward).
- the robot's front carries the bucket ladder; its rear (-x at heading 0) carries the two
  docking buttons at its rear-left and rear-right corners and dumps over the rear.

With a `Layout` (`firmware_like.arena`) the world also holds the arena's rocks, craters and
terrain (`firmware_like.terrain`): the chassis rests on its four wheels, so it pitches and
rolls over the ground, a crater's rim and a rock it runs into; a rock stops it; a wheel deep
in a crater traps it. The world keeps the referee's truth (SPEC 6.1: collisions, crater
entries, delivered kg) for the referee only: the autonomy sees the world through its sensors.

Wiring as built (the YAML compensates with polarity): positive duty rolls a LEFT wheel
forward but a RIGHT wheel backward (mirrored mounting); `ble.chain_left` positive and
`ble.chain_right` negative run the chain in its digging direction; `ble.lift_motor`
positive extends the actuator, raising the bin.
"""

from __future__ import annotations

import bisect
import math
import random
from collections.abc import Iterable
from typing import Any, NamedTuple

from firmware_like.arena import (
    Layout,
    Pose,
    StartSpec,
    collector_span,
    footprint_corners,
    random_layout,
    region_of,
    seeded_start,
    start_pose,
)
from firmware_like.arena_floor import ArenaFloor
from firmware_like.arena_params import ArenaParams
from firmware_like.bucket_ladder import CHAINS, LIFT, BucketLadderExcavator, clipped_gauss
from firmware_like.marte_params import MarteParams
from firmware_like.terrain import Terrain

LEFT_WHEELS = ("base.lf_wheel", "base.lb_wheel")
RIGHT_WHEELS = ("base.rf_wheel", "base.rb_wheel")
WHEELS = LEFT_WHEELS + RIGHT_WHEELS
MOTORS = WHEELS + CHAINS + (LIFT,)
ANALOG_INPUTS = ("base.battery", "ble.lift_pot")
DIGITAL_INPUTS = ("base.l_button", "base.r_button")
DIGITAL_OUTPUTS = ("base.user_led", "base.led_high", "base.led_mid", "base.led_low")
BRIDGE_INPUTS = ("ble.load_cell",)

# Sign from a wheel motor's duty to rolling forward (the BLE's are in its own part).
_MOUNT: dict[str, float] = {
    "base.lf_wheel": 1.0, "base.lb_wheel": 1.0,
    "base.rf_wheel": -1.0, "base.rb_wheel": -1.0,
}

REGIONS = ("start", "obstacle", "dig")

_tuple_new = tuple.__new__


class ImuTruth(NamedTuple):
    """The chassis' true motion, for an IMU emulator (SPEC frame, body axes x forward, y left,
    z up). Angles are Z-Y-X Euler angles in radians: `roll` positive left side up, `pitch`
    positive nose down, `yaw` counter-clockwise from +x in [-pi, pi]. `angular_velocity`
    (rad/s, p q r about body x y z) and `linear_acceleration` (m/s^2, WITHOUT gravity) are
    in the body axes. An accelerometer reads the specific force, linear_acceleration +
    g * (-sin pitch, cos pitch sin roll, cos pitch cos roll) with g = 9.80665, so a level
    robot at rest reads (0, 0, +g). Rates and accelerations are finite differences over the
    last physics piece (at most `MarteParams.max_step`); `time` is the world time they
    refer to."""

    time: float
    roll: float
    pitch: float
    yaw: float
    angular_velocity: tuple[float, float, float]
    linear_acceleration: tuple[float, float, float]

    # The names the IMU emulator's truth contract reads (`firmware_like.imu`), so the world's
    # own truth serves it with no adapter.
    @property
    def omega_body(self) -> tuple[float, float, float]:
        return self.angular_velocity

    @property
    def accel_body(self) -> tuple[float, float, float]:
        return self.linear_acceleration


class ChassisPose(NamedTuple):
    """Where the chassis is: footprint centre (x, y) and the height z (m) of the plane under
    its wheels there, and its attitude (roll, pitch, yaw in rad, as in ImuTruth)."""

    x: float
    y: float
    z: float
    roll: float
    pitch: float
    yaw: float


def _known(name: str, kind: str, known: Iterable[str]) -> None:
    """Raise KeyError naming every valid signal, so a typo in YAML is easy to spot."""
    names = tuple(known)
    if name not in names:
        raise KeyError(f"unknown {kind} {name!r}; known: {', '.join(names)}")


class MarteWorld:
    """MARTE in the RMC arena: pose, attitude, motors, battery, lift, bin, collector, and
    (with a layout) rocks, craters, terrain and the referee's counts.

    `layout` None: an empty arena with level ground, the robot in the middle of the start
    region facing +x (what the backend's `ramp run --sim` drives). With a layout, the robot
    starts at `start_pose(layout.start, seed)` (a start drawn from the seed when the layout
    has none) and `seed` also draws the ground's undulation. `MarteWorld.seeded(seed)` is
    the SPEC's random arena.

    Public state for tests and benchmarks: `x`, `y` (m, centre of the footprint),
    `heading` (rad, counter-clockwise from +x, in [-pi, pi]; `yaw` is the same),
    `heading_deg`, `z`, `roll`, `pitch` (chassis attitude, see `ImuTruth`), `bin_kg`,
    `delivered_kg`, `spilled_kg`, `excavated_kg`, `lift_pos` (0 retracted/digging ..
    1 extended/dumping), `battery_voltage` (terminal, V), `battery_current` (A),
    `battery_soc` (0..1), `time` (s of simulated time), and the referee's truth
    `collisions`, `crater_entries` (counts of contacts begun, SPEC 6.1), `collision_log`,
    `crater_log` ((time, what) of each), `trapped` (a wheel stuck in a crater).
    """

    def __init__(self, params: MarteParams | None = None, seed: int = 0,
                 layout: Layout | None = None, arena: ArenaParams | None = None) -> None:
        self.params = params if params is not None else MarteParams()
        self.arena = arena if arena is not None else ArenaParams()
        p = self.params
        self.seed = seed
        self._rng = random.Random(seed)
        self._ocv_soc = [s for s, _ in p.ocv_curve]
        self._ocv_volts = [v * p.battery_cells for _, v in p.ocv_curve]
        self._duty: dict[str, float] = dict.fromkeys(WHEELS, 0.0)
        # Each wheel motor's speed as a fraction of its free speed at `motor_ref_voltage`, in
        # the motor's own sense (positive duty -> positive speed).
        self._speed: dict[str, float] = dict.fromkeys(WHEELS, 0.0)
        self._outputs: dict[str, bool] = dict.fromkeys(DIGITAL_OUTPUTS, False)
        self._unplugged: set[str] = set()
        self._wheel_scale = dict(zip(WHEELS, p.wheel_speed_scale, strict=True))
        # Two derived params (properties of the frozen params) the physics reads every piece.
        self._free_speed = p.wheel_free_speed
        self._capacity_c = p.battery_capacity_c
        #: The Bucket Ladder Excavator, a part of its own that this chassis carries and steps
        #: (`firmware_like.bucket_ladder`); the `ble` module's signals are its.
        self.ble = BucketLadderExcavator(self.params)
        self.time = 0.0
        #: Moves on whenever what the read_* methods return may have changed (a step, a
        #: placement), so a reader need not sample again while it stands still.
        self.revision = 0
        #: The floor this chassis stands on, a part of its own: the RMC arena's walls, rocks,
        #: craters and terrain, and the referee's counts (`firmware_like.arena_floor`).
        self.floor = ArenaFloor(p, self.arena, seed, layout)
        self.z = self.roll = self.pitch = 0.0
        self._velocity = (0.0, 0.0, 0.0)  # world frame, over the last piece (for the IMU)
        self._imu = ImuTruth(0.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        if layout is None:
            # Start in the middle of the starting region, facing the digging region.
            self.x = p.start_region_end / 2.0 + 0.1
            self.y = p.arena_width / 2.0
            self.heading = 0.0
            self.start: StartSpec | None = None
        else:
            self.start = layout.start if layout.start is not None else seeded_start(seed)
            pose = start_pose(self.start, seed, p, self.arena)
            self.x, self.y = pose.x, pose.y
            self.heading = math.remainder(math.radians(pose.yaw_deg), 2.0 * math.pi)
        self.start_pose = Pose(self.x, self.y, self.heading_deg)
        self._settle()
        self.battery_soc = p.initial_soc
        self.battery_current = p.idle_current
        self.battery_voltage = self._ocv(self.battery_soc) - self.battery_current * (
            p.battery_r_internal)
        self._noise: dict[str, float] = {}
        self._sample_noise()

    @classmethod
    def seeded(cls, seed: int, start_box: str | None = None, heading_deg: float | None = None,
               params: MarteParams | None = None, arena: ArenaParams | None = None,
               ) -> MarteWorld:
        """The SPEC 6.1 arena drawn from a seed: three rocks, two craters, a start box and
        heading (unless given), the start pose perturbed, the ground's undulation."""
        p = params if params is not None else MarteParams()
        a = arena if arena is not None else ArenaParams()
        layout = random_layout(seed, p, a, start_box, heading_deg)
        return cls(p, seed=seed, layout=layout, arena=a)

    # ---- commands and readings (the SimWorld protocol of ramp/hal/simio.py) -------------

    def set_motor(self, name: str, duty: float) -> None:
        """Command one motor; duty is clamped to -1..1 as a motor controller would."""
        if name not in MOTORS:
            _known(name, "motor", MOTORS)
        duty = float(duty)
        if not math.isfinite(duty):
            raise ValueError(f"duty for {name} must be finite, got {duty!r}")
        duties = self.ble.duty if self.ble.owns_motor(name) else self._duty
        duties[name] = max(-1.0, min(1.0, duty))

    def duty(self, name: str) -> float:
        """The duty last commanded to a motor (what the controller is applying now)."""
        _known(name, "motor", MOTORS)
        return self.ble.duty[name] if self.ble.owns_motor(name) else self._duty[name]

    def read_analog(self, name: str) -> float:
        """Volts at the ADC pin, as sampled at the last step."""
        if name not in ANALOG_INPUTS:
            _known(name, "analog input", ANALOG_INPUTS)
        p = self.params
        if name != "base.battery":
            return self.ble.read_pot()
        volts = p.v_sensor_offset + p.v_sensor_gain * self.battery_voltage
        return volts + self._noise[name]

    def read_digital(self, name: str) -> bool:
        """Docking buttons: closed while that rear corner touches the collector wall x = 0."""
        if name not in DIGITAL_INPUTS:
            _known(name, "digital input", DIGITAL_INPUTS)
        corner = self._corners()[2 if name == "base.l_button" else 3]
        return corner[0] <= self.params.button_travel

    def write_digital(self, name: str, on: bool) -> None:
        """Set an LED output."""
        _known(name, "digital output", DIGITAL_OUTPUTS)
        self._outputs[name] = bool(on)

    def output(self, name: str) -> bool:
        """Read back an LED output."""
        _known(name, "digital output", DIGITAL_OUTPUTS)
        return self._outputs[name]

    def read_bridge(self, name: str) -> float:
        """Load cell ratio in mV/V: an offset for the empty bin plus the regolith's weight."""
        if name not in BRIDGE_INPUTS:
            _known(name, "bridge input", BRIDGE_INPUTS)
        return self.ble.read_load_cell()

    def bus_present(self, bus: str) -> bool:
        """False between `unplug(bus)` and `replug(bus)`; any bus name is accepted."""
        return bus not in self._unplugged

    # ---- test and benchmark controls -------------------------------------------------------

    def unplug(self, bus: str) -> None:
        """Make a bus disappear, as a pulled USB cable would."""
        self._unplugged.add(bus)

    def replug(self, bus: str) -> None:
        """Bring an unplugged bus back."""
        self._unplugged.discard(bus)

    def sensor_reading(self, name: str, quantity: float) -> float | bool:
        """What input `name` reads (noise-free) when the quantity it senses is `quantity`:
        the battery sensor at `quantity` rail volts, the lift pot at position `quantity`
        (0 retracted .. 1 extended), the load cell with `quantity` kg in the bin, a docking
        button pressed (non-zero) or not. For a simulated input override (a low battery, a
        pressed button) that goes through the same sensor model as the physics."""
        p = self.params
        if name in DIGITAL_INPUTS:
            return quantity != 0
        if name == "base.battery":
            return p.v_sensor_offset + p.v_sensor_gain * quantity
        _known(name, "input", ANALOG_INPUTS + BRIDGE_INPUTS)
        return self.ble.sensor_reading(name, quantity)

    def jam_lift(self, jammed: bool) -> None:
        """Stall the lift actuator in place (it draws stall current and does not move)."""
        self.ble.lift_jammed = bool(jammed)

    def place(self, x: float, y: float, heading_deg: float) -> None:
        """Set the pose (heading counter-clockwise from +x); the footprint must lie inside
        the arena. A teleport for tests and tools: the chassis settles on the terrain there,
        and contacts it starts in are not counted (only contacts begun by driving are)."""
        p = self.params
        old = (self.x, self.y, self.heading)
        self.x, self.y = float(x), float(y)
        self.heading = math.remainder(math.radians(heading_deg), 2.0 * math.pi)
        xs = [c[0] for c in self._corners()]
        ys = [c[1] for c in self._corners()]
        eps = 1e-9
        if min(xs) < -eps or max(xs) > p.arena_length + eps or min(ys) < -eps or (
                max(ys) > p.arena_width + eps):
            self.x, self.y, self.heading = old
            raise ValueError(f"pose ({x}, {y}, {heading_deg} deg) puts the robot outside "
                             f"the {p.arena_length} x {p.arena_width} m arena")
        self._settle()
        self.revision += 1

    # ---- derived state ------------------------------------------------------------------------

    @property
    def heading_deg(self) -> float:
        """Heading in degrees, counter-clockwise from +x, in [-180, 180]."""
        return math.degrees(self.heading)

    @property
    def yaw(self) -> float:
        """Heading in radians, counter-clockwise from +x (SPEC 6.1's yaw)."""
        return self.heading

    def chassis_pose(self) -> ChassisPose:
        """Position and attitude of the chassis, for the LIDAR's view of the arena."""
        return ChassisPose(self.x, self.y, self.z, self.roll, self.pitch, self.heading)

    def imu_truth(self) -> ImuTruth:
        """The chassis' true attitude and motion for an IMU emulator (see `ImuTruth`):
        roll, pitch, yaw (rad, Z-Y-X, SPEC frame), body angular velocity (rad/s) and body
        linear acceleration without gravity (m/s^2), as of the last step."""
        return self._imu

    def describe(self) -> dict[str, object]:
        """The true world, as the header of a trace (SPEC 6.3 `--trace`): arena, robot,
        rocks, craters and start (box, heading and the exact pose, yaw in degrees)."""
        p, a = self.params, self.arena
        start: dict[str, object] = {"x": self.start_pose.x, "y": self.start_pose.y,
                                    "yaw": self.start_pose.yaw_deg}
        if self.start is not None:
            start = {"box": self.start.box, "heading": self.start.heading_deg, **start}
        return {
            "arena": {"length": p.arena_length, "width": p.arena_width,
                      "start_end_x": p.start_region_end, "start_split_y": a.start_split_y,
                      "obstacle_end_x": p.dig_region_start, "collector_y": p.collector_y,
                      "collector_width": p.collector_width, "wall_height": a.wall_height},
            "robot": {"length": p.robot_length, "width": p.robot_width},
            "rocks": [{"x": r.x, "y": r.y, "d": r.d, "height": r.height}
                      for r in self.layout.rocks],
            "craters": [{"x": c.x, "y": c.y, "d": c.d, "depth": c.depth}
                        for c in self.layout.craters],
            "start": start,
            "world": self.layout.source,
        }

    def truth(self) -> dict[str, float | int | bool]:
        """The referee's ground truth now (SPEC 6.1, 6.3 trace fields): never for the
        autonomy."""
        return {
            "t": self.time, "x": self.x, "y": self.y, "yaw": self.heading_deg,
            "lift": self.lift_pos, "bin_kg": self.bin_kg, "delivered_kg": self.delivered_kg,
            "collisions": self.collisions, "crater_entries": self.crater_entries,
            "trapped": self.trapped,
        }

    @property
    def lift_jammed(self) -> bool:
        return self.ble.lift_jammed

    @property
    def digging(self) -> bool:
        """True while the last step moved regolith into the bin."""
        return self.ble.digging

    # The arena's state and the referee's counts, through the robot as before.
    @property
    def layout(self) -> Layout:
        return self.floor.layout

    @property
    def terrain(self) -> Terrain:
        return self.floor.terrain

    @property
    def collisions(self) -> int:
        return self.floor.collisions

    @property
    def crater_entries(self) -> int:
        return self.floor.crater_entries

    @property
    def collision_log(self) -> list[tuple[float, str]]:
        return self.floor.collision_log

    @property
    def crater_log(self) -> list[tuple[float, str]]:
        return self.floor.crater_log

    @property
    def trapped(self) -> bool:
        return self.floor.trapped

    # The BLE's state, through the robot as before (the referee, traces; tests set it).
    @property
    def lift_pos(self) -> float:
        return self.ble.lift_pos

    @lift_pos.setter
    def lift_pos(self, value: float) -> None:
        self.ble.lift_pos = value

    @property
    def bin_kg(self) -> float:
        return self.ble.bin_kg

    @bin_kg.setter
    def bin_kg(self, value: float) -> None:
        self.ble.bin_kg = value

    @property
    def delivered_kg(self) -> float:
        return self.ble.delivered_kg

    @delivered_kg.setter
    def delivered_kg(self, value: float) -> None:
        self.ble.delivered_kg = value

    @property
    def spilled_kg(self) -> float:
        return self.ble.spilled_kg

    @spilled_kg.setter
    def spilled_kg(self, value: float) -> None:
        self.ble.spilled_kg = value

    @property
    def excavated_kg(self) -> float:
        return self.ble.excavated_kg

    @excavated_kg.setter
    def excavated_kg(self, value: float) -> None:
        self.ble.excavated_kg = value

    def wheel_speed(self, name: str) -> float:
        """Ground speed of one wheel in m/s, positive rolling the robot forward."""
        _known(name, "wheel", WHEELS)
        return self._wheel_ground_speed(name)

    def motor_speed(self, name: str) -> float:
        """Motor speed as a fraction of free speed at the reference voltage, in duty sense."""
        _known(name, "motor", MOTORS)
        return self.ble.speed[name] if self.ble.owns_motor(name) else self._speed[name]

    def region(self) -> str:
        """Arena region of the robot's centre: "start", "obstacle" or "dig"."""
        return region_of(self.x, self.params)

    def front_x(self) -> float:
        """x of the middle of the front edge (where the bucket ladder is)."""
        return self.x + 0.5 * self.params.robot_length * math.cos(self.heading)

    def rear_x(self) -> float:
        """x of the middle of the rear edge (where the bin dumps and the buttons sit)."""
        return self.x - 0.5 * self.params.robot_length * math.cos(self.heading)

    def at_collector(self) -> bool:
        """True when regolith dumped now counts as delivered (SPEC 6.1): the rear of the
        robot (both rear corners) within `dump_reach` (0.15 m) of the x = 0 wall and within
        the collector's width."""
        p = self.params
        rear_left, rear_right = self._corners()[2:]
        if max(rear_left[0], rear_right[0]) > p.dump_reach:
            return False
        lo, hi = collector_span(p)
        return min(rear_left[1], rear_right[1]) >= lo and max(rear_left[1], rear_right[1]) <= hi

    def state(self) -> dict[str, float | str | bool]:
        """A snapshot of everything a benchmark would log."""
        return {
            "time": self.time, "x": self.x, "y": self.y, "heading_deg": self.heading_deg,
            "region": self.region(), "lift_pos": self.lift_pos, "bin_kg": self.bin_kg,
            "delivered_kg": self.delivered_kg, "spilled_kg": self.spilled_kg,
            "excavated_kg": self.excavated_kg, "battery_voltage": self.battery_voltage,
            "battery_current": self.battery_current, "battery_soc": self.battery_soc,
            "digging": self.ble.digging, "lift_jammed": self.ble.lift_jammed,
            "z": self.z, "roll_deg": math.degrees(self.roll),
            "pitch_deg": math.degrees(self.pitch), "collisions": self.collisions,
            "crater_entries": self.crater_entries, "trapped": self.trapped,
        }

    # ---- integration --------------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """Advance the world by dt seconds, in pieces no longer than `params.max_step`."""
        dt = float(dt)
        if not math.isfinite(dt) or dt < 0.0:
            raise ValueError(f"dt must be a finite number >= 0, got {dt!r}")
        if dt == 0.0:
            return
        if dt != self._pieces_dt:  # a run steps by the same dt, tick after tick
            self._pieces_dt = dt
            pieces = max(1, math.ceil(dt / self.params.max_step - 1e-9))
            self._pieces = (pieces, dt / pieces)
        pieces, h = self._pieces
        for _ in range(pieces):
            self._substep(h)
        self._sample_noise()
        self.revision += 1

    def _substep(self, dt: float) -> None:
        p = self.params
        # Motors: first-order lag toward duty x (rail voltage / reference voltage). The rail
        # voltage is the previous piece's, which keeps the battery-motor loop explicit.
        volt_factor = max(0.0, self.battery_voltage) / p.motor_ref_voltage
        if dt != self._alpha_dt:  # every piece of a run is usually as long as the last
            self._alpha_dt = dt
            self._alpha = 1.0 - math.exp(-dt / p.motor_time_constant)
        alpha = self._alpha
        duty, speed = self._duty, self._speed
        for name in WHEELS:
            target = duty[name] * volt_factor
            speed[name] += (target - speed[name]) * alpha
        self.ble.follow_duty(volt_factor, alpha)
        self._move_chassis(dt)
        self.ble.move_lift(dt)
        self.ble.dig_and_dump(dt, self.front_x(), self.at_collector)
        self._drain_battery(dt)
        self.time += dt

    def _move_chassis(self, dt: float) -> None:
        p = self.params
        x0, y0, z0, yaw0, roll0, pitch0 = (self.x, self.y, self.z, self.heading, self.roll,
                                           self.pitch)
        # The mean ground speed of each side (`_wheel_ground_speed` written out), summed as
        # sum() over the side's wheels did (0.0 first, then in order).
        sp, sc, free = self._speed, self._wheel_scale, self._free_speed
        lf, lb = LEFT_WHEELS
        rf, rb = RIGHT_WHEELS
        left = (0.0 + _MOUNT[lf] * sp[lf] * free * sc[lf] + _MOUNT[lb] * sp[lb] * free * sc[lb]
                ) / 2.0
        right = (0.0 + _MOUNT[rf] * sp[rf] * free * sc[rf] + _MOUNT[rb] * sp[rb] * free * sc[rb]
                 ) / 2.0
        left *= self.floor.traction * p.traction
        right *= self.floor.traction * p.traction
        v = 0.5 * (left + right)
        # Counter-clockwise positive: the right side running faster turns the robot left.
        yaw_rate = p.skid_efficiency * (right - left) / p.track_width
        mid = self.heading + 0.5 * yaw_rate * dt
        self.x += v * math.cos(mid) * dt
        self.y += v * math.sin(mid) * dt
        self.heading = math.remainder(self.heading + yaw_rate * dt, 2.0 * math.pi)
        self.floor.hold(self)  # `_clamp_to_arena`, then `_push_off_rocks` among rocks
        self._update_contacts(count=True)
        self._update_attitude()
        self._update_imu(dt, x0, y0, z0, yaw0, roll0, pitch0)

    # The arena's part (firmware_like/arena_floor.py): walls, rocks, craters and terrain act on
    # this chassis; these keep the chassis' own names for them.
    def _push_off_rocks(self) -> None:
        self.floor.push_off_rocks(self)

    def contacts(self) -> list[str]:
        """What the footprint touches now (walls, rocks, craters), as the referee names
        them; empty when it stands clear."""
        hits, craters = self._contacts()
        return sorted(hits | craters)

    def _contacts(self) -> tuple[set[str], set[str]]:
        return self.floor.contacts(self)

    def _update_contacts(self, count: bool) -> None:
        self.floor.update_contacts(self, count)

    def _update_attitude(self) -> None:
        self.floor.rest(self)

    def _update_imu(self, dt: float, x0: float, y0: float, z0: float, yaw0: float,
                    roll0: float, pitch0: float) -> None:
        """Finite differences over this piece: body rates and acceleration (no gravity)."""
        vx, vy, vz = (self.x - x0) / dt, (self.y - y0) / dt, (self.z - z0) / dt
        pvx, pvy, pvz = self._velocity
        self._velocity = (vx, vy, vz)
        ax, ay, az = (vx - pvx) / dt, (vy - pvy) / dt, (vz - pvz) / dt
        droll = (self.roll - roll0) / dt
        dpitch = (self.pitch - pitch0) / dt
        dyaw = math.remainder(self.heading - yaw0, 2.0 * math.pi) / dt
        cr, sr = math.cos(self.roll), math.sin(self.roll)
        cp, sp = math.cos(self.pitch), math.sin(self.pitch)
        cy, sy = math.cos(self.heading), math.sin(self.heading)
        gyro = (droll - dyaw * sp, dpitch * cr + dyaw * cp * sr, -dpitch * sr + dyaw * cp * cr)
        # Body = R^T world, R = Rz(yaw) Ry(pitch) Rx(roll).
        r1 = cy * ax + sy * ay  # undo yaw
        r2 = -sy * ax + cy * ay
        b1 = cp * r1 - sp * az  # undo pitch
        b3 = sp * r1 + cp * az
        accel = (b1, cr * r2 + sr * b3, -sr * r2 + cr * b3)  # undo roll
        # ImuTruth(...) without its generated __new__'s Python-level call: the same tuple.
        self._imu = _tuple_new(ImuTruth, (self.time + dt, self.roll, self.pitch, self.heading,
                                          gyro, accel))

    def _settle(self) -> None:
        """After a teleport: rest on the terrain, take contacts as they are, zero the IMU."""
        self._update_attitude()
        self._update_contacts(count=False)
        self._velocity = (0.0, 0.0, 0.0)
        self._imu = ImuTruth(self.time, self.roll, self.pitch, self.heading, (0.0, 0.0, 0.0),
                             (0.0, 0.0, 0.0))

    def _clamp_to_arena(self) -> None:
        self.floor.clamp(self)

    def _drain_battery(self, dt: float) -> None:
        p = self.params
        current = p.idle_current
        duty, amps = self._duty, p.wheel_current
        for name in WHEELS:
            current += abs(duty[name]) * amps
        current = self.ble.add_current(current)
        self.battery_current = current
        self.battery_soc = max(0.0, self.battery_soc - current * dt / self._capacity_c)
        ocv = self._ocv(self.battery_soc)
        self.battery_voltage = max(0.0, ocv - current * p.battery_r_internal)

    # ---- helpers ------------------------------------------------------------------------------

    def _wheel_ground_speed(self, name: str) -> float:
        return (_MOUNT[name] * self._speed[name] * self._free_speed
                * self._wheel_scale[name])

    def _ocv(self, soc: float) -> float:
        """Open-circuit voltage of the pack, interpolated in the per-cell curve."""
        socs, volts = self._ocv_soc, self._ocv_volts
        soc = min(1.0, max(0.0, soc))
        i = bisect.bisect_right(socs, soc)
        if i >= len(socs):
            return volts[-1]
        s0, s1 = socs[i - 1], socs[i]
        v0, v1 = volts[i - 1], volts[i]
        return v0 + (v1 - v0) * (soc - s0) / (s1 - s0)

    def corners(self) -> tuple[tuple[float, float], ...]:
        """Footprint corners (see `_corners`), for the floor this chassis stands on."""
        return self._corners()

    def _corners(self) -> tuple[tuple[float, float], ...]:
        """Footprint corners: front-left, front-right, rear-left, rear-right (world x, y),
        worked out again only when the pose moved (the docking buttons read them every
        tick)."""
        pose = (self.x, self.y, self.heading)
        if pose != self._corners_pose:
            p = self.params
            self._corners_pose = pose
            self._corners_at = footprint_corners(self.x, self.y, self.heading,
                                                 p.robot_length, p.robot_width)
        return self._corners_at

    _corners_pose: tuple[float, float, float] | None = None
    _corners_at: tuple[tuple[float, float], ...] = ()
    _pieces_dt = math.nan  # the dt `_pieces` ((how many, how long) of `step`) was worked for
    _pieces: tuple[int, float] = (1, 0.0)
    _alpha_dt = math.nan  # the piece length `_alpha` (the motors' lag factor) was worked for
    _alpha = 0.0

    def _sample_noise(self) -> None:
        """Draw this step's sensor noise once, so repeated reads agree and runs repeat."""
        self._noise["base.battery"] = clipped_gauss(self._rng, self.params.v_sensor_noise)
        self.ble.sample_noise(self._rng)


def marte_part(ctx: Any, module: str, config: Any) -> MarteWorld:
    """`ramp.emulators` entry `module.base`: MARTE's chassis (this model; the rig's seeded
    one when it handed one in, an empty arena otherwise). Its floor, the arena, is shared as
    "floor" for any other part that stands on it."""
    world: MarteWorld = ctx.shared("marte", MarteWorld)
    ctx.shared("floor", lambda: world.floor)
    return world


def ble_part(ctx: Any, module: str, config: Any) -> BucketLadderExcavator:
    """`ramp.emulators` entry `module.ble`: the Bucket Ladder Excavator part, carried (and
    stepped, see `firmware_like.bucket_ladder`) by MARTE's chassis."""
    world: MarteWorld = ctx.shared("marte", MarteWorld)
    return world.ble
