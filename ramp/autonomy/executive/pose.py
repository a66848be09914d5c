"""Where the robot is between two localizations: the last fix, moved by dead reckoning.

The localizer fixes the pose only from scans taken standing still; in between, the pose is
the fix moved by what odometry says the wheels did (the distance) and what the gyro says the
chassis turned (the heading: a skid-steer's heading from its wheel commands is the first thing
to go wrong on real ground, a gyro's is good for the seconds between two fixes; before the
AHRS has settled, odometry's turn stands in). The confidence starts at the localizer's and
falls with the distance driven and the angle turned since, so the mission stops to localize
again before it would drive on a guess, and never drives without a fix at all: a lost
tracker has no pose.

`tick(now, dt)` runs after odometry's and the AHRS's tasks and writes `ctx.pose`,
`ctx.pose_confidence` and `ctx.pose_time_s` of the `MissionContext` it is bound to, every
tick, before the mission's own tick reads them.

Odometry's distances are scaled by `distance_scale`, learnt from the fixes: a robot whose
traction or wheel speeds are not the model's (`ramp sim mission --randomize`, or real ground)
covers more or less ground than its commands say. At each confident fix after a drive of at
least `SCALE_MIN_M`, the fix's displacement from the previous fix, projected on the
dead-reckoned one, over the dead-reckoned one's length, is how far off the scale was; the
scale moves halfway there (geometrically), within `SCALE_LIMITS`. Headings come from the gyro,
so the dead-reckoned path has the right shape and only its length is in question.
"""

from __future__ import annotations

import math

from ramp.autonomy.odometry import Odometry, Pose2, between
from ramp.autonomy.perception.ahrs import Ahrs
from ramp.autonomy.planning import Pose
from ramp.statemachine import MissionContext

SCALE_MIN_M = 0.5  # a shorter drive says too little about the scale (fixes are +-2 cm)
SCALE_MIN_CONFIDENCE = 0.8  # only fixes this sure teach the scale
SCALE_LIMITS = (0.75, 1.25)  # traction +-15 % and wheel speeds +-5 %, with room


class PoseTracker:
    """The pose estimate the executive drives by; see the module docstring."""

    def __init__(self, odometry: Odometry, ahrs: Ahrs | None = None, *,
                 decay_m: float = 5.0, decay_rad: float = 4.0 * math.pi) -> None:
        if not (decay_m > 0 and decay_rad > 0):
            raise ValueError("pose tracker: decay lengths must be > 0")
        self.odometry = odometry
        self.ahrs = ahrs
        self.decay_m = decay_m
        self.decay_rad = decay_rad
        self.ctx: MissionContext | None = None
        self._pose: Pose2 | None = None  # arena frame, dead-reckoned since the last fix
        self._lost = True
        self._prior_ok = False  # the dead-reckoned pose is worth a prior while lost
        self.fix_confidence = 0.0
        self.fix_time = math.nan
        self.distance_m = 0.0  # driven since the fix
        self.turned_rad = 0.0  # turned since the fix
        self.lost_reason = "not localized yet"
        self.fixes = 0
        self._odom: Pose2 = odometry.pose
        self._gyro: float | None = None
        self.distance_scale = 1.0  # ground covered per metre odometry says (learnt)
        self._fixed_at: Pose2 | None = None  # the last fix, for the next scale estimate

    # -- what the localizer and the activities tell it -----------------------------------------
    def bind(self, ctx: MissionContext) -> None:
        self.ctx = ctx
        self._publish()

    def fix(self, now: float, x: float, y: float, yaw: float, confidence: float) -> None:
        """A localization from scans taken at `now` with the robot standing still."""
        self._learn_scale(float(x), float(y), float(confidence))
        self._pose = (float(x), float(y), math.remainder(float(yaw), 2 * math.pi))
        self._lost = False
        self._prior_ok = True
        self.fix_confidence = max(0.0, min(1.0, float(confidence)))
        self.fix_time = now
        self.distance_m = self.turned_rad = 0.0
        self.lost_reason = ""
        self.fixes += 1
        self._fixed_at = self._pose if confidence >= SCALE_MIN_CONFIDENCE else None
        self._reference()
        self._publish()

    def lose(self, reason: str, *, keep_prior: bool = True) -> None:
        """No pose any more: a failed localization (the dead-reckoned pose stays a prior for
        the next try), or an operator who may have moved the robot anywhere (`keep_prior`
        False: nothing is known but the gyro's heading)."""
        self._lost = True
        self._fixed_at = None  # a drive from an unknown start teaches nothing
        self._prior_ok = self._prior_ok and keep_prior
        self.fix_confidence = 0.0
        self.lost_reason = reason
        self._publish()

    @property
    def lost(self) -> bool:
        return self._lost

    @property
    def pose(self) -> Pose2 | None:
        """(x, y, yaw) now, None while lost."""
        return None if self._lost else self._pose

    @property
    def prior(self) -> Pose2 | None:
        """The dead-reckoned pose to hand the localizer as a prior, lost or not; None when
        nothing is known (never fixed, or moved by someone else)."""
        return self._pose if self._prior_ok else None

    @property
    def confidence(self) -> float:
        if self.pose is None:
            return 0.0
        return self.fix_confidence * math.exp(-self.distance_m / self.decay_m
                                              - self.turned_rad / self.decay_rad)

    def estimate(self) -> Pose | None:
        return None if self.pose is None else Pose(*self.pose)

    # -- the task ------------------------------------------------------------------------------
    def tick(self, now: float, dt: float) -> None:
        odom = self.odometry.pose
        fwd, left, odom_turn = between(self._odom, odom)
        fwd *= self.distance_scale
        left *= self.distance_scale
        self._odom = odom
        gyro = self._gyro_yaw()
        turn = odom_turn
        if gyro is not None and self._gyro is not None:
            turn = math.remainder(gyro - self._gyro, 2 * math.pi)
        self._gyro = gyro
        if self._pose is not None and (fwd or left or turn):
            x, y, yaw = self._pose
            mid = yaw + 0.5 * turn
            c, s = math.cos(mid), math.sin(mid)
            self._pose = (x + c * fwd - s * left, y + s * fwd + c * left,
                         math.remainder(yaw + turn, 2 * math.pi))
            self.distance_m += math.hypot(fwd, left)
            self.turned_rad += abs(turn)
        self._publish()

    # -- inside -------------------------------------------------------------------------------
    def _learn_scale(self, x: float, y: float, confidence: float) -> None:
        """Compare the fix with where dead reckoning put the robot since the last fix."""
        start, dead = self._fixed_at, self._pose
        if start is None or dead is None or self._lost or confidence < SCALE_MIN_CONFIDENCE:
            return
        dx, dy = dead[0] - start[0], dead[1] - start[1]
        length = math.hypot(dx, dy)
        if length < SCALE_MIN_M:
            return
        ratio = ((x - start[0]) * dx + (y - start[1]) * dy) / (length * length)
        if not math.isfinite(ratio) or ratio <= 0.0:
            return
        lo, hi = SCALE_LIMITS
        self.distance_scale = min(hi, max(lo, self.distance_scale * math.sqrt(ratio)))

    def _gyro_yaw(self) -> float | None:
        ahrs = self.ahrs
        if ahrs is None or not ahrs.settled:
            return None
        return ahrs.yaw

    def _reference(self) -> None:
        self._odom = self.odometry.pose
        self._gyro = self._gyro_yaw()

    def _publish(self) -> None:
        ctx = self.ctx
        if ctx is None:
            return
        ctx.pose = self.estimate()
        ctx.pose_confidence = self.confidence
        ctx.pose_time_s = self.fix_time
