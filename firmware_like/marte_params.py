"""Every number the MARTE physics model uses, each with where it comes from.

Sources: "thesis p.N" is the page of ../shared/thesis (chapter 5); "RMC 2014" is the
competition rules as summarised in the thesis and the SPEC; "hw-facts" is
../shared/reference/hardware-facts.md; "SPEC" is ../shared/SPEC.md (paths from a checkout
next to the shared folder). Anything else is
marked ASSUMPTION with the reason for the value chosen. Units are SI unless the name says
otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class MarteParams:
    """Parameters of the MARTE world (arena, chassis, battery, excavator, sensors)."""

    # ---- arena (RMC 2014; thesis p.30, SPEC 6) -------------------------------------------
    arena_length: float = 7.38  # m along x; thesis p.30 "7.38 x 3.88 meter arena"
    arena_width: float = 3.88  # m along y; thesis p.30
    start_region_end: float = 1.5  # m; RMC 2014 rules: starting region 0-1.5 m
    dig_region_start: float = 4.44  # m; RMC 2014 rules: obstacle region 2.94 m, 1.5 + 2.94
    # The collector bin is centred on the outside of the starting region's 3.88 m wall
    # (thesis p.30), i.e. the wall x = 0, centred at y = 3.88 / 2.
    collector_y: float = 1.94  # m; thesis p.30 (centre of the 3.88 m wall)
    collector_width: float = 1.65  # m; SPEC 6.1 (the RMC collector bin's width)
    dump_reach: float = 0.15  # m; SPEC 6.1: regolith is delivered only while the rear is
    # within 0.15 m of the x = 0 wall (and within the collector's width)
    qualify_kg: float = 10.0  # kg in 10 min to qualify; thesis p.30, SPEC 6
    run_time: float = 600.0  # s; "within 10 minutes", thesis p.30

    # ---- chassis (thesis p.34) ---------------------------------------------------------------
    # RMC 2014 limits the robot to 1.5 m x 0.75 m; MARTE's footprint is not in the thesis.
    robot_length: float = 1.2  # m along the heading; SPEC 6.1 "1.2 m x 0.75 m"
    robot_width: float = 0.75  # m; SPEC 6.1
    track_width: float = 0.65  # m between left and right wheel centres; ASSUMPTION
    # m between front and rear axles; ASSUMPTION: the wheels sit at the footprint's ends
    # (1.2 m footprint - one 0.3048 m wheel diameter)
    wheelbase: float = 0.895
    wheel_width: float = 0.10  # m; ASSUMPTION (a 4-inch-wide wheel, typical for 12-inch ones)
    wheel_diameter: float = 0.3048  # m; thesis p.34 "12 inches in diameter"
    gear_ratio: float = 256.0  # thesis p.34 "343 oz-in motors, each paired with 256:1 gearboxes"
    # Motor free speed is not in the thesis. ASSUMPTION: 4800 rpm at `motor_ref_voltage`,
    # which gives 4800 / 256 = 18.75 wheel rpm = 0.30 m/s ground speed, a plausible top speed
    # for a 256:1 drive. (343 oz-in is the stall torque of the common CIM-class 12 V motor.)
    motor_free_rpm: float = 4800.0
    motor_ref_voltage: float = 20.0  # V at which the free speeds hold; ASSUMPTION (fresh pack
    # under moderate load); speeds scale with rail voltage / this.
    motor_time_constant: float = 0.15  # s; first-order lag of every motor; ASSUMPTION (brief)
    # Skid-steer: yaw rate = efficiency * (v_left - v_right) / track_width. Wheels slip
    # sideways when a skid-steer turns, so the chassis turns slower than the wheel speeds
    # imply. ASSUMPTION: 0.6, in the usual 0.5-0.9 range for grousered wheels in loose soil.
    skid_efficiency: float = 0.6
    # Ground speed over wheel speed (1: no slip), and each wheel's own speed error in WHEELS'
    # order (lf, lb, rf, rb): 1 on the model, drawn by --randomize (firmware_like.randomize).
    traction: float = 1.0
    wheel_speed_scale: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    button_travel: float = 0.01  # m; rear corner within this of the wall closes the button;
    # ASSUMPTION (plunger travel of a small push button)

    # ---- battery (thesis p.34) ---------------------------------------------------------------
    # "two 5000 mAh 18.5 V LiPo batteries wired in parallel" -> 5S, 10 Ah; rail 17-21 V.
    battery_capacity_ah: float = 10.0  # thesis p.34 (2 x 5000 mAh in parallel)
    # Open-circuit voltage per cell against state of charge, a generic LiPo shape; ASSUMPTION.
    # Ends chosen to match the thesis p.34 rail "17 to 21 volt": 5 x 3.40 V empty,
    # 5 x 4.20 V full.
    ocv_curve: tuple[tuple[float, float], ...] = (
        (0.00, 3.40), (0.05, 3.55), (0.10, 3.64), (0.20, 3.71), (0.40, 3.79),
        (0.60, 3.87), (0.80, 4.00), (0.90, 4.08), (1.00, 4.20),
    )
    battery_cells: int = 5  # 18.5 V nominal / 3.7 V; thesis p.34
    # Two packs of ~20 mOhm each in parallel plus harness, fuses and the safety switch.
    # ASSUMPTION; at 4 wheels full (4 x 15 A) it sags the rail by ~1.8 V.
    battery_r_internal: float = 0.03  # ohm
    initial_soc: float = 1.0  # state of charge at the start of a run; ASSUMPTION (fresh packs)

    # ---- currents (per motor, drawn from the rail; all ASSUMPTIONS) -------------------------
    # Battery current of a PWM-driven motor under a steady load torque is about
    # duty x load current, so each draw is modelled as |duty| x the figure below. A 343 oz-in
    # (2.42 N m) CIM-class motor stalls at roughly 130 A at 12 V; driving and digging loads
    # are a fraction of that.
    idle_current: float = 1.5  # A; SBC, Phidgets, router, controllers
    wheel_current: float = 15.0  # A per wheel motor at full duty while driving in regolith
    chain_current: float = 8.0  # A per chain motor at full duty, ladder free-running
    dig_current: float = 6.0  # A extra per chain motor at full chain speed while digging
    lift_current: float = 4.0  # A, Thompson actuator moving at full duty
    lift_stall_current: float = 12.0  # A, actuator stalled (jammed or pushing an end stop)

    # ---- bucket ladder excavator (thesis p.35, SPEC 2.1) ------------------------------------
    lift_stroke_time: float = 10.0  # s for a full stroke at full duty; SPEC 2.1 "about 10 s"
    bucket_count: int = 24  # thesis p.35 "24 steel buckets" (informative; rate below is lumped)
    dig_lift_max: float = 0.15  # lift position below which the ladder is in the soil; brief
    dig_rate: float = 0.3  # kg/s at full chain speed; ASSUMPTION (~18 kg/min, gives 10 kg in
    # well under the 10-minute run with travel time)
    bin_capacity: float = 40.0  # kg; ASSUMPTION (aluminium storage bin, thesis p.35)
    dump_lift_min: float = 0.8  # lift position above which regolith slides out; ASSUMPTION
    dump_rate: float = 3.0  # kg/s while dumping; ASSUMPTION (a full bin empties in ~13 s)

    # ---- sensors --------------------------------------------------------------------------------
    # Phidget 1135 voltage sensor: Vout = 2.5 + 0.0681 * V (hw-facts section 2).
    v_sensor_offset: float = 2.5  # V; hw-facts 2
    v_sensor_gain: float = 0.0681  # V/V; hw-facts 2
    v_sensor_noise: float = 0.0015  # V standard deviation, clipped to 3 sigma; ASSUMPTION
    pot_retracted_volts: float = 0.6  # V at position 0; brief (ASSUMPTION about the actuator)
    pot_extended_volts: float = 4.4  # V at position 1; brief
    pot_noise: float = 0.0015  # V standard deviation, clipped to 3 sigma; ASSUMPTION
    load_cell_offset: float = 0.25  # mV/V from the empty bin's own weight; brief
    load_cell_gain: float = 0.02  # mV/V per kg (50 kg per mV/V); brief
    load_cell_noise: float = 0.0003  # mV/V standard deviation, clipped to 3 sigma; ASSUMPTION

    # ---- integration ------------------------------------------------------------------------
    max_step: float = 0.05  # s; longer steps are split into pieces no longer than this

    def __post_init__(self) -> None:
        socs = [p[0] for p in self.ocv_curve]
        if socs[0] != 0.0 or socs[-1] != 1.0 or socs != sorted(set(socs)):
            raise ValueError("ocv_curve must run from soc 0.0 to 1.0 in increasing order")
        for name in ("arena_length", "arena_width", "robot_length", "robot_width",
                     "track_width", "wheelbase", "wheel_width", "wheel_diameter", "gear_ratio",
                     "motor_free_rpm",
                     "motor_ref_voltage", "motor_time_constant", "battery_capacity_ah",
                     "lift_stroke_time", "bin_capacity", "dump_rate", "max_step"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if not 0.0 < self.skid_efficiency <= 1.0:
            raise ValueError("skid_efficiency must be in (0, 1]")
        if not 0.0 <= self.initial_soc <= 1.0:
            raise ValueError("initial_soc must be in 0..1")

    @property
    def wheel_free_speed(self) -> float:
        """Ground speed (m/s) of a wheel at full duty and `motor_ref_voltage`."""
        return self.motor_free_rpm / self.gear_ratio * math.pi * self.wheel_diameter / 60.0

    @property
    def battery_capacity_c(self) -> float:
        """Battery capacity in coulombs, for integrating current."""
        return self.battery_capacity_ah * 3600.0
