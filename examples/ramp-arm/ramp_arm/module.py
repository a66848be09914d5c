"""The `arm` module type: three RC-servo joints and a gripper, written against `ramp.api` only.

YAML (each joint a `servo` device, the gripper a `digital_out`):

    arm:
      type: arm
      shoulder: {bus: arm_servos, channel: 0, min: -10, max: 100, speed: 60, stow: 0}
      elbow:    {bus: arm_servos, channel: 1, min: -120, max: 120, speed: 90, stow: 90}
      wrist:    {bus: arm_servos, channel: 2, min: -90, max: 90, speed: 120, stow: 0}
      gripper:  {bus: arm_io, channel: 0}
      arm: {tolerance: 2.0}

Requests: `JOINT.pos=(deg)` within the joint's limits (motion), `gripper.close=(0|1)`
(motion), `arm.stow=()` (every joint to its stow angle), `arm.stop=()` (every joint holds
where it is). `arm.get=()`: each joint's `pos` (what the servo controller reports) and
`target`, `gripper.close`, and `arm.stowed` (1 while every joint is within `tolerance` of its
stow angle: what an interlock watches before fast driving).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ramp.api import (
    Block,
    DeviceSpec,
    DigitalOutput,
    Field,
    FlagParam,
    FloatParam,
    Function,
    Module,
    Property,
    Rule,
    ServoChannel,
)

JOINTS = ("shoulder", "elbow", "wrist")

#: A joint's own YAML keys, beside its bus's channel keys. Angles in degrees.
JOINT_FIELDS = Block(
    {
        "min": Field(float, -90.0, -180.0, 180.0, what="the lowest angle in degrees"),
        "max": Field(float, 90.0, -180.0, 180.0, what="the highest angle in degrees"),
        "speed": Field(float, 60.0, 1.0, 720.0, what="a speed limit in deg/s"),
        "stow": Field(float, 0.0, -180.0, 180.0, what="the stowed angle in degrees"),
    },
    rules=(
        Rule(lambda v: v["min"] < v["max"], "min must be below max"),
        Rule(lambda v: v["min"] <= v["stow"] <= v["max"], "stow must lie within min..max",
             "stow"),
    ),
)
ARM_FIELDS = Block({
    "tolerance": Field(float, 2.0, 0.1, 20.0, what="an angle in degrees"),
})


class Joint:
    """One servo joint: its limits, speed and stow angle, and what it was last sent."""

    def __init__(self, channel: ServoChannel, params: Mapping[str, Any]) -> None:
        self.channel = channel
        self.lo, self.hi = float(params["min"]), float(params["max"])
        self.speed = float(params["speed"])
        self.stow_deg = float(params["stow"])

    @property
    def pos(self) -> float:
        return self.channel.read()

    @property
    def target(self) -> float:
        """The angle commanded; where it is when nothing is (NaN before the first reading)."""
        t = self.channel.target
        return self.pos if t is None else t

    def move(self, deg: float) -> None:
        self.channel.move(deg, self.speed)

    def moving(self, tolerance: float) -> bool:
        t, p = self.channel.target, self.pos
        return t is not None and math.isfinite(p) and abs(t - p) > tolerance


class ArmModule(Module):
    """A 3-joint arm with a gripper."""

    devices: ClassVar[dict[str, DeviceSpec]] = {
        **{j: DeviceSpec("servo", JOINT_FIELDS, f"{j} joint (an RC servo)") for j in JOINTS},
        "gripper": DeviceSpec("digital_out", Block(), "gripper solenoid: on closes it"),
    }
    settings: ClassVar[dict[str, Block]] = {"arm": ARM_FIELDS}

    def __init__(self, name: str, devices: Mapping[str, Any],
                 settings: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        super().__init__(name)
        self.joints = {j: Joint(*self.device(devices, j, ServoChannel)) for j in JOINTS}
        self.gripper: DigitalOutput = self.device(devices, "gripper", DigitalOutput)[0]
        self.tolerance = float(self.setting(settings, "arm")["tolerance"])

        for j, joint in self.joints.items():
            self.add(Function(j, "pos", (FloatParam(joint.lo, joint.hi),), joint.move,
                              "motion", f"move the {j} to an angle in degrees"))
        self.add(Function("gripper", "close", (FlagParam(),), self._grip, "motion",
                          "close (1) or open (0) the gripper"))
        self.add(Function(name, "stow", (), self.stow, "motion",
                          "every joint to its stowed angle", moves=JOINTS))
        for j, joint in self.joints.items():
            self.prop(Property(j, "pos", "float", _reader(joint, "pos"), "deg"))
            self.prop(Property(j, "target", "float", _reader(joint, "target"), "deg"))
        self.prop(Property("gripper", "close", "int", lambda: int(self.gripper.state)))
        self.prop(Property(name, "stowed", "int", lambda: int(self.stowed())))

    def _grip(self, close: int) -> None:
        self.gripper.write(bool(close))

    def stow(self) -> None:
        for joint in self.joints.values():
            joint.move(joint.stow_deg)

    def stowed(self) -> bool:
        return all(math.isfinite(j.pos) and abs(j.pos - j.stow_deg) <= self.tolerance
                   for j in self.joints.values())

    def stop(self) -> None:
        """Every joint holds where it is; the gripper keeps its grip (letting go on a stop
        would drop what it holds)."""
        for joint in self.joints.values():
            joint.channel.hold()

    def is_moving(self) -> bool:
        return any(j.moving(self.tolerance) for j in self.joints.values())


def _reader(joint: Joint, attr: str) -> Any:
    return lambda: getattr(joint, attr)
