"""Path following: pose in, `base:base.drive` speed and direction out.

The follower drives a `Path` the way the planner checked it: it turns in place at the start
and at each corner until it faces along the next straight stretch (or away from it, when the
path is driven in reverse), then tracks that stretch with pure pursuit (a lookahead point on
the stretch's line, extended past its end so the robot settles onto the line rather than
aiming at a point beside it). It slows down before every stop, since a 1.2 m robot that
overshoots a corner sweeps where nobody checked. It never looks past the current corner:
cutting corners would take the footprint off the checked sweep.

Output is SPEC 2.3's `(speed %, direction deg)`: direction 0 ahead, 180 back, +90 spins
clockwise; left = s(cos d + sin d), right = s(cos d - sin d) scaled so the larger is |s|.
The wanted body speed and turn rate become wheel percentages through the robot model
(`ramp.autonomy.robot_model`), and those become `(s, d)` exactly.

Pure: no clock, no I/O. Call `update(pose)` at the control rate; it keeps only which stretch
it is on and whether it is turning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ramp.autonomy.planning.geometry import Pose, wrap_angle
from ramp.autonomy.planning.path import FloatArray, Path, corner_indices
from ramp.autonomy.robot_model import MARTE, RobotModel, drive_command

FOLLOWING, TURNING, DONE, OFF_PATH = "following", "turning", "done", "off_path"


@dataclass(frozen=True)
class FollowerConfig:
    """Speed limits (base.drive %) and tolerances."""

    max_speed_pct: float = 60.0  # straight driving
    min_speed_pct: float = 12.0  # floor while slowing for a stop (1 % steps are coarse below)
    turn_speed_pct: float = 60.0  # fastest spin in place
    min_turn_pct: float = 8.0
    turn_gain: float = 2.0  # spin rate (rad/s) per rad of heading error, before limits
    lookahead_m: float = 0.30
    slow_down_m: float = 0.40  # ramp the speed down over this distance before a stop
    # A stretch ends this short of its corner at most: the planner checked the turn there
    # keeping 1.5 cm (the start region's fine grid) to 2.5 cm, so stopping 3 cm short of a
    # corner by a wall put a spin's corner into it.
    goal_tolerance_m: float = 0.01
    turn_start_rad: float = math.radians(20.0)  # heading error mid-stretch that stops it to turn
    turn_done_rad: float = math.radians(2.0)  # ... and the error at which turning ends
    off_path_m: float = 0.20  # cross-track error that gives up (the caller re-plans)


@dataclass(frozen=True)
class DriveCommand:
    """One `base:base.drive=(speed,direction)` and what the follower is doing."""

    speed: int  # -100..100 (the follower always gives >= 0; direction carries the sense)
    direction: float  # degrees, -180..180
    status: str  # following, turning, done, off_path
    cross_track_m: float = 0.0  # signed, + when the robot is left of the path
    remaining_m: float = 0.0  # along the path to its end

    @property
    def request(self) -> str:
        """The MCP request text."""
        return f"base:base.drive=({self.speed},{self.direction:g})"


class PathFollower:
    """Follows one `Path`; make a new one (or call `reset`) for the next leg."""

    def __init__(self, path: Path, config: FollowerConfig | None = None,
                 model: RobotModel = MARTE) -> None:
        self.config = config or FollowerConfig()
        self.model = model
        self.reset(path)

    def reset(self, path: Path) -> None:
        self.path = path
        pts = path.points
        self._corners = [pts[k] for k in corner_indices(pts)] if len(pts) > 1 else [pts[0]]
        self._stretch = 0
        self._turning = True  # line up with the first stretch before moving
        self._final_turn = len(self._corners) < 2
        self.status = FOLLOWING
        self._kept: tuple[int, list[FloatArray], tuple[FloatArray, float, FloatArray, float,
                                                       float, bool]] | None = None

    @property
    def done(self) -> bool:
        return self.status == DONE

    def update(self, pose: Pose) -> DriveCommand:
        """The command for this control step."""
        if self.status in (DONE, OFF_PATH):
            return DriveCommand(0, 0.0, self.status)
        if self._final_turn:
            return self._turn_to_final(pose)
        cfg = self.config
        a, seg_len, u, seg_dir, rest, stops = self._geometry()
        here = np.array([pose.x, pose.y])
        rel = here - a
        along = float(rel @ u)
        cross = float(u[0] * rel[1] - u[1] * rel[0])
        remaining = max(0.0, seg_len - along) + rest
        if along >= seg_len - cfg.goal_tolerance_m:
            return self._arrive(pose, cross, remaining)
        if abs(cross) > cfg.off_path_m:
            self.status = OFF_PATH
            return DriveCommand(0, 0.0, OFF_PATH, cross, remaining)
        motion_yaw = wrap_angle(pose.yaw + math.pi) if self.path.reverse else pose.yaw
        err = wrap_angle(seg_dir - motion_yaw)
        if self._turning and abs(err) <= cfg.turn_done_rad:
            self._turning = False
        elif not self._turning and abs(err) > cfg.turn_start_rad:
            self._turning = True
        if self._turning:
            return self._spin(err, cross, remaining)
        # Pure pursuit on the stretch's line, in the frame of the direction of motion.
        target = a + u * (along + cfg.lookahead_m)
        d = target - here
        c, s = math.cos(motion_yaw), math.sin(motion_yaw)
        lx, ly = c * d[0] + s * d[1], -s * d[0] + c * d[1]
        curvature = 2.0 * ly / max(lx * lx + ly * ly, 1e-9)
        to_stop = seg_len - along if stops else math.inf
        pct = cfg.max_speed_pct
        if to_stop < cfg.slow_down_m:
            # A constant deceleration (speed ~ the root of the distance left): speed falling in
            # proportion to the distance crept the last decimetres at the floor, 2-3 s a stop.
            pct = max(cfg.min_speed_pct,
                      cfg.max_speed_pct * math.sqrt(to_stop / cfg.slow_down_m))
        v = pct / 100.0 * self.model.wheel_free_speed_m_s
        omega = v * curvature
        if self.path.reverse:
            v = -v
        left, right = self.model.wheel_percents(v, omega)
        biggest = max(abs(left), abs(right))
        if biggest > pct:  # keep the curvature, cap the faster wheel
            left, right = left * pct / biggest, right * pct / biggest
        return self._command(left, right, FOLLOWING, cross, remaining)

    # -- pieces --------------------------------------------------------------------------------
    def _geometry(self) -> tuple[FloatArray, float, FloatArray, float, float, bool]:
        """(start corner, length, unit direction, its heading, the path's length after
        this stretch, whether the robot stops at its end) of the current stretch: worked out
        once when the stretch begins (they depend on the corners and the stretch alone)."""
        k, corners = self._stretch, self._corners
        kept = self._kept
        if kept is not None and kept[0] == k and kept[1] is corners:
            return kept[2]
        a, b = corners[k], corners[k + 1]
        seg = b - a
        seg_len = float(math.hypot(seg[0], seg[1]))
        u = seg / seg_len
        rest = self._rest()
        geometry = (a, seg_len, u, math.atan2(float(u[1]), float(u[0])), rest,
                    self._stops_after(k))
        self._kept = (k, corners, geometry)
        return geometry

    def _rest(self) -> float:
        """The path's length after the current stretch."""
        return sum(float(np.hypot(*(q - p))) for p, q in
                   zip(self._corners[self._stretch + 1:], self._corners[self._stretch + 2:],
                       strict=False))

    def _remaining(self, along: float, seg_len: float) -> float:
        return max(0.0, seg_len - along) + self._rest()

    def _stops_after(self, k: int) -> bool:
        """True when the robot must stop at the end of stretch k: the end, or any corner it
        must turn at. The planner checked a turn in place there; pure pursuit through a
        shallow corner lags the new heading for a few decimetres, and the footprint's
        outer front corner swings up to several centimetres wide of the checked sweep (an
        18 deg corner took one into a crater)."""
        if k + 2 >= len(self._corners):
            return True
        d1 = self._corners[k + 1] - self._corners[k]
        d2 = self._corners[k + 2] - self._corners[k + 1]
        turn = wrap_angle(math.atan2(d2[1], d2[0]) - math.atan2(d1[1], d1[0]))
        return abs(turn) > self.config.turn_done_rad

    def _arrive(self, pose: Pose, cross: float, remaining: float) -> DriveCommand:
        """End of a stretch: on to the next, or the final turn, or done."""
        self._stretch += 1
        if self._stretch + 1 < len(self._corners):
            self._turning = self._stops_after(self._stretch - 1)
            return self.update(pose)
        self._final_turn = True
        return self._turn_to_final(pose)

    def _turn_to_final(self, pose: Pose) -> DriveCommand:
        if self.path.final_yaw is None:
            self.status = DONE
            return DriveCommand(0, 0.0, DONE)
        err = wrap_angle(self.path.final_yaw - pose.yaw)
        if abs(err) <= self.config.turn_done_rad:
            self.status = DONE
            return DriveCommand(0, 0.0, DONE)
        return self._spin(err, 0.0, 0.0)

    def _spin(self, err: float, cross: float, remaining: float) -> DriveCommand:
        """Turn in place toward a heading error (rad, + counter-clockwise)."""
        cfg = self.config
        omega = cfg.turn_gain * err
        _left, right = self.model.wheel_percents(0.0, omega)
        pct = min(cfg.turn_speed_pct, max(cfg.min_turn_pct, abs(right)))
        sign = 1.0 if err > 0 else -1.0
        return self._command(-sign * pct, sign * pct, TURNING, cross, remaining)

    def _command(self, left: float, right: float, status: str, cross: float,
                 remaining: float) -> DriveCommand:
        speed, direction = drive_command(left, right)
        speed_int = round(speed)
        if speed_int == 0 and speed > 0:
            speed_int = 1
        return DriveCommand(speed_int, round(direction, 1), status, cross, remaining)
