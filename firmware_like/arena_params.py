"""Every number of the arena world and the LIDAR's view of it, each with where it comes from.

Sources as in `marte_params.py`: "SPEC" is ../shared/SPEC.md (section 6.1 defines the
arena, its obstacles and the referee; 6.2 the sensors); "thesis p.N" is a page of the thesis;
"UTM-30LX-EW sheet" is Hokuyo's specification sheet of the scanner. Anything else is marked
ASSUMPTION with the reason for the value chosen. The arena's length, width, regions and
collector live in `MarteParams` (the physics model's own copy); here is what the obstacles,
the terrain, the referee and the LIDAR add. Units are SI unless the name says otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# Hit kinds of a LIDAR beam (what it hit), shared by the ray-caster and the plots.
HIT_NONE = 0
HIT_WALL = 1
HIT_GROUND = 2
HIT_ROCK = 3
HIT_CRATER = 4
HIT_FRAME = 5
HIT_DUST = 6
HIT_NAMES = ("none", "wall", "ground", "rock", "crater", "frame", "dust")


@dataclass(frozen=True)
class ArenaParams:
    """Walls, start boxes, obstacles, terrain and referee of the RMC arena (SPEC 6.1)."""

    # ---- walls and start boxes -----------------------------------------------------------
    wall_height: float = 1.0  # m; SPEC 6.1 "at least 1 m tall": the lowest legal wall, so a
    # LIDAR pitched up by the terrain loses the walls as early as it could in the real arena
    start_split_y: float = 1.94  # m; SPEC 6.1: right box y < 1.94, left box y >= 1.94
    start_yaw_jitter_deg: float = 10.0  # SPEC 6.1 "up to +-10 deg"
    start_xy_jitter: float = 0.2  # m; SPEC 6.1 "+-0.2 m"
    start_margin: float = 0.02  # m the footprint keeps from the box's edges and the walls;
    # ASSUMPTION: judges do not place a robot touching a wall (that would be a collision)
    collector_depth: float = 0.45  # m the bin reaches behind the x = 0 wall; ASSUMPTION, only
    # drawn on maps (the referee needs the bin's width alone)

    # ---- obstacles (SPEC 6.1; thesis p.31 "three rocks and two craters") -------------------
    rock_count: int = 3
    crater_count: int = 2
    rock_d_min: float = 0.10  # m; SPEC 6.1
    rock_d_max: float = 0.30  # m; SPEC 6.1
    rock_height_ratio_min: float = 0.5  # height / diameter; SPEC 6.1 "as tall as half their
    # diameter or more"
    rock_height_ratio_max: float = 0.8  # ASSUMPTION: field rocks are seldom taller than this
    crater_d_min: float = 0.15  # m; SPEC 6.1
    crater_d_max: float = 0.30  # m; SPEC 6.1
    crater_depth_min: float = 0.10  # m; ASSUMPTION: shallower is a dent, not a crater
    crater_depth_max: float = 0.30  # m; SPEC 6.1 "up to 0.30 m deep"
    obstacle_gap: float = 0.05  # m between any two obstacles' discs; ASSUMPTION, so "not
    # overlapping" holds with room to tell them apart
    # World files that give no height/depth: a rock as tall as 0.6 of its diameter (inside
    # the SPEC's range), a crater as deep as half its diameter, at most crater_depth_max.
    default_rock_height_ratio: float = 0.6  # ASSUMPTION
    default_crater_depth_ratio: float = 0.5  # ASSUMPTION

    # ---- terrain ---------------------------------------------------------------------------
    # Regolith is raked flat between runs but never level: three gentle plane waves whose
    # amplitudes add up to at most `ground_amplitude`. ASSUMPTION: +-2 cm over 1.5-3.5 m, a
    # slope of at most ~5 deg, enough for a tilted LIDAR to see texture, not enough to hide
    # a rock.
    ground_amplitude: float = 0.02  # m
    ground_waves: int = 3
    ground_wavelength_min: float = 1.5  # m
    ground_wavelength_max: float = 3.5  # m

    # ---- how the robot meets obstacles ------------------------------------------------------
    # A driven wheel climbs a rock's flank before the rock stops the robot: the footprint may
    # overlap a rock's disc by this much (at most the rock's radius), which tilts the
    # chassis; any deeper and it is pushed back. ASSUMPTION: a 12-inch grousered wheel
    # (thesis p.34) gets ~8 cm onto a 0.2 m dome, its lowest point ~9 cm up, before it
    # stalls; the chassis then leans ~3 deg.
    rock_ride_up: float = 0.08  # m
    # A wheel sinking into a crater loses traction: ground speed scales down linearly with
    # the deepest wheel's sink, to `crater_slow_min` at `crater_trap_sink`; at that sink or
    # deeper the wheel cannot climb back out and the robot is trapped. ASSUMPTION: a driven
    # wheel in loose regolith climbs a step of at most half its 0.15 m radius. (A 0.30 m
    # crater centred under a 0.10 m wide wheel lets it sink 0.095 m; a 0.25 m one 0.05 m.)
    crater_trap_sink: float = 0.075  # m
    crater_slow_min: float = 0.3  # fraction of ground speed just before the trap

    # ---- referee (SPEC 6.1) --------------------------------------------------------------------
    docking_tolerance: float = 0.02  # m; SPEC 6.1: the rear touching the x = 0 wall at the
    # collector "within 2 cm" is docking, not a collision
    contact_epsilon: float = 1e-6  # m; a footprint this close to a wall touches it (float
    # rounding of the wall clamp), ASSUMPTION

    def __post_init__(self) -> None:
        for name in ("wall_height", "rock_d_min", "rock_d_max", "crater_d_min", "crater_d_max",
                     "crater_depth_min", "crater_depth_max", "ground_wavelength_min",
                     "ground_wavelength_max", "crater_trap_sink"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if self.rock_d_min > self.rock_d_max or self.crater_d_min > self.crater_d_max:
            raise ValueError("obstacle diameter ranges must have min <= max")
        if not 0.0 <= self.crater_slow_min <= 1.0:
            raise ValueError("crater_slow_min must be in 0..1")
        if self.ground_amplitude < 0.0:
            raise ValueError("ground_amplitude must be >= 0")


@dataclass(frozen=True)
class FrameBox:
    """A piece of the robot's own structure the LIDAR can see, as a box in the chassis frame
    (x forward, y left, z up from the ground plane under the wheels; metres)."""

    x0: float
    x1: float
    y0: float
    y1: float
    z0: float
    z1: float


@dataclass(frozen=True)
class LidarParams:
    """The Hokuyo UTM-30LX-EW and where it sits on MARTE."""

    steps: int = 1081  # steps 0..1080; SPEC 6.2 (PP AMIN 0, AMAX 1080)
    front_step: int = 540  # SPEC 6.2 (PP AFRT)
    steps_per_turn: int = 1440  # SPEC 6.2 (PP ARES): 0.25 deg per step, +-135 deg in all
    range_min: float = 0.1  # m; SPEC 6.2, UTM-30LX-EW sheet
    range_max: float = 30.0  # m; SPEC 6.2, UTM-30LX-EW sheet (guaranteed range)
    # UTM-30LX-EW sheet, "repeated accuracy": sigma < 10 mm at 0.1-10 m, < 30 mm at 10-30 m.
    noise_sigma_near: float = 0.010  # m
    noise_sigma_far: float = 0.030  # m
    noise_far_from: float = 10.0  # m
    # A step with no echo reads as an error code below DMIN (23 mm in PP). ASSUMPTION: code 1,
    # which the UTM family reports when the reflected light is too weak (nothing in range).
    no_return_mm: int = 1
    # Dust: a beam now and then returns from a puff of regolith between the scanner and its
    # target (thesis p.74: the localization scan "captured the BLE frame and dust").
    # ASSUMPTION: 0.2 % of beams per scan at rest, 1 % while the ladder digs, at 0.15-1.5 m.
    dust_probability: float = 0.002
    dust_probability_digging: float = 0.01
    dust_range_min: float = 0.15  # m
    dust_range_max: float = 1.5  # m
    # Where the pan/tilt unit puts the scanner's optical centre on the chassis, with pan and
    # tilt at zero: x forward of the footprint's centre, y left, z above the ground plane
    # under the wheels. ASSUMPTION: at the front of the chassis, above the bucket ladder's
    # drive, 0.70 m up so that a level scan sees the 1 m walls and a scan tilted 15-20 deg
    # down meets the ground 2-3 m ahead, across the obstacle region.
    mount_x: float = 0.40  # m
    mount_y: float = 0.0  # m
    mount_z: float = 0.70  # m
    mount_yaw: float = 0.0  # rad, the pan axis' zero off the chassis' +x (--randomize)
    # The robot's own structure in view (thesis fig. 5.38): the BLE's two frame posts behind
    # and beside the scanner, seen at +-125..135 deg at about 0.4 m. ASSUMPTION: 4 cm posts
    # from the chassis deck to the bin's top edge.
    frame: tuple[FrameBox, ...] = (
        FrameBox(0.13, 0.17, 0.31, 0.35, 0.20, 0.95),
        FrameBox(0.13, 0.17, -0.35, -0.31, 0.20, 0.95),
    )

    def __post_init__(self) -> None:
        if not 0 <= self.front_step < self.steps:
            raise ValueError("front_step must be one of the steps")
        if not 0.0 < self.range_min < self.range_max:
            raise ValueError("need 0 < range_min < range_max")
        if not 0 <= self.no_return_mm < 23:
            raise ValueError("no_return_mm must be an error code below DMIN (23 mm)")
        for name in ("dust_probability", "dust_probability_digging"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in 0..1")

    @property
    def step_angle(self) -> float:
        """Radians between two steps (2 pi / ARES)."""
        return 2.0 * math.pi / self.steps_per_turn
