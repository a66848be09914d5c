"""MARTE's Bucket Ladder Excavator as a part of the simulated world: the chain, the lift
actuator, the bin and its load cell (the `ble` module's signals).

The BLE rides on MARTE's chassis and shares its battery, so it is stepped by the chassis,
inside each of the chassis' physics pieces (`MarteWorld.step`): its motors follow their duty
on the rail voltage the chassis' battery gives, it digs where the chassis' front is in the
digging region and dumps where the chassis' rear is at the collector, and its currents add to
the battery's load. It has no `step` of its own for the same reason. The order of every
floating point operation is the one MARTE's single model had, so a seeded run gives the same
result to the last bit.

Wiring as built: `ble.chain_left` positive and `ble.chain_right` negative run the chain in its
digging direction; `ble.lift_motor` positive extends the actuator, raising the bin.
"""

from __future__ import annotations

import random
from collections.abc import Callable

from firmware_like.marte_params import MarteParams

CHAINS = ("ble.chain_left", "ble.chain_right")
LIFT = "ble.lift_motor"
MOTORS = CHAINS + (LIFT,)
ANALOG_INPUTS = ("ble.lift_pot",)
BRIDGE_INPUTS = ("ble.load_cell",)

# Sign from a motor's duty to its useful direction (chain digging, lift up).
MOUNT: dict[str, float] = {"ble.chain_left": 1.0, "ble.chain_right": -1.0, LIFT: 1.0}


def clipped_gauss(rng: random.Random, sigma: float) -> float:
    """Gaussian noise clipped at 3 sigma; no draw at all for sigma 0 (runs repeat)."""
    if sigma <= 0.0:
        return 0.0
    # max(-3 sigma, min(3 sigma, x)) as two comparisons, which pick the same value.
    hi = 3.0 * sigma
    x = rng.gauss(0.0, sigma)
    x = x if x < hi else hi
    lo = -hi
    return x if x > lo else lo


class BucketLadderExcavator:
    """Chain, lift, bin and load cell. Public state: `lift_pos` (0 retracted/digging ..
    1 extended/dumping), `bin_kg`, `delivered_kg`, `spilled_kg`, `excavated_kg`."""

    def __init__(self, params: MarteParams) -> None:
        self.params = params
        self.duty: dict[str, float] = dict.fromkeys(MOTORS, 0.0)
        # Each motor's speed as a fraction of its free speed at `motor_ref_voltage`.
        self.speed: dict[str, float] = dict.fromkeys(MOTORS, 0.0)
        self.lift_jammed = False
        self.lift_blocked = False
        self.digging = False
        self.chain_dig_speed = 0.0
        self.lift_pos = 0.0
        self.bin_kg = 0.0
        self.delivered_kg = 0.0
        self.spilled_kg = 0.0
        self.excavated_kg = 0.0
        self.noise: dict[str, float] = {}

    # ---- signals --------------------------------------------------------------------------
    def owns_motor(self, name: str) -> bool:
        return name in self.duty

    def read_pot(self) -> float:
        """Volts at the lift potentiometer's ADC pin."""
        p = self.params
        span = p.pot_extended_volts - p.pot_retracted_volts
        return p.pot_retracted_volts + span * self.lift_pos + self.noise["ble.lift_pot"]

    def read_load_cell(self) -> float:
        """Load cell ratio in mV/V: an offset for the empty bin plus the regolith's weight."""
        p = self.params
        return p.load_cell_offset + p.load_cell_gain * self.bin_kg + self.noise["ble.load_cell"]

    def sensor_reading(self, name: str, quantity: float) -> float:
        """What the pot reads at lift position `quantity`, the load cell with `quantity` kg
        in the bin (noise-free); KeyError for any other name."""
        p = self.params
        if name == "ble.lift_pot":
            return p.pot_retracted_volts + (p.pot_extended_volts - p.pot_retracted_volts) * (
                quantity)
        if name == "ble.load_cell":
            return p.load_cell_offset + p.load_cell_gain * quantity
        raise KeyError(name)

    # ---- integration, called by the chassis in each of its pieces --------------------------
    def follow_duty(self, volt_factor: float, alpha: float) -> None:
        """Motors: first-order lag toward duty x (rail voltage / reference voltage)."""
        for name in MOTORS:
            target = self.duty[name] * volt_factor
            self.speed[name] += (target - self.speed[name]) * alpha

    def move_lift(self, dt: float) -> None:
        p = self.params
        duty = self.duty[LIFT]
        at_top = self.lift_pos >= 1.0 and duty > 0.0
        at_bottom = self.lift_pos <= 0.0 and duty < 0.0
        if self.lift_jammed or at_top or at_bottom:
            # A stalled screw does not turn: the motor is held at zero speed.
            self.speed[LIFT] = 0.0
            self.lift_blocked = duty != 0.0
            return
        self.lift_blocked = False
        pos = self.lift_pos + self.speed[LIFT] / p.lift_stroke_time * dt
        if pos >= 1.0 or pos <= 0.0:
            pos = min(1.0, max(0.0, pos))
            self.speed[LIFT] = 0.0
        self.lift_pos = pos

    def dig_and_dump(self, dt: float, front_x: float, at_collector: Callable[[], bool]) -> None:
        """Dig while the chain runs with the ladder down and the chassis' front (`front_x`)
        in the digging region; dump while the bin is raised, delivered when the chassis is
        `at_collector()`, spilled otherwise."""
        p = self.params
        # Both chain motors drive one belt: its speed is their mean in the digging sense
        # (summed as sum() over CHAINS did: 0.0 first, then in order).
        left, right = CHAINS
        speed = self.speed
        chain = (0.0 + MOUNT[left] * speed[left] + MOUNT[right] * speed[right]) / 2.0
        self.chain_dig_speed = max(0.0, chain)
        in_soil = self.lift_pos < p.dig_lift_max
        in_dig_region = front_x >= p.dig_region_start
        self.digging = False
        if chain > 0.0 and in_soil and in_dig_region:
            room = max(0.0, p.bin_capacity - self.bin_kg)
            dug = min(room, p.dig_rate * chain * dt)
            if dug > 0.0:
                self.bin_kg += dug
                self.excavated_kg += dug
                self.digging = True
        if self.lift_pos > p.dump_lift_min and self.bin_kg > 0.0:
            out = min(self.bin_kg, p.dump_rate * dt)
            self.bin_kg -= out
            if at_collector():
                self.delivered_kg += out
            else:
                self.spilled_kg += out

    def add_current(self, current: float) -> float:
        """The battery current with the BLE's motors' added (in the model's order)."""
        p = self.params
        for name in CHAINS:
            current += abs(self.duty[name]) * p.chain_current
            if self.digging:
                current += p.dig_current * self.chain_dig_speed
        lift_amps = p.lift_stall_current if self.lift_blocked else p.lift_current
        current += abs(self.duty[LIFT]) * lift_amps
        return current

    def sample_noise(self, rng: random.Random) -> None:
        """Draw this step's sensor noise (after the chassis' draws, from the same stream)."""
        p, noise = self.params, self.noise
        noise["ble.lift_pot"] = clipped_gauss(rng, p.pot_noise)
        noise["ble.load_cell"] = clipped_gauss(rng, p.load_cell_noise)
