"""The arm's physics for `ramp run --sim`: three RC servos and a gripper (a world part).

Registered as `ramp.emulators` entry `module.arm`. Each joint's controller ramps toward its
target at the commanded speed limit and reports where it is, as a Phidget RCServo does; a
joint starts at its stow angle. The gripper is closed while its output is on.
"""

from __future__ import annotations

from typing import Any

JOINTS = ("shoulder", "elbow", "wrist")


class ArmPart:
    """Owns the signals `MODULE.shoulder`, `.elbow`, `.wrist` (servos), `MODULE.gripper`."""

    def __init__(self, module: str, start: dict[str, float]) -> None:
        self.module = module
        self.pos = {j: start.get(j, 0.0) for j in JOINTS}
        self.target: dict[str, float | None] = dict.fromkeys(JOINTS)
        self.speed = dict.fromkeys(JOINTS, 0.0)
        self.gripper_closed = False
        self.revision = 0

    def _device(self, name: str, known: tuple[str, ...]) -> str:
        module, _, device = name.partition(".")
        if module != self.module or device not in known:
            raise KeyError(name)
        return device

    def set_servo(self, name: str, target_deg: float | None, speed_dps: float) -> None:
        j = self._device(name, JOINTS)
        self.target[j], self.speed[j] = target_deg, speed_dps

    def read_servo(self, name: str) -> float:
        return self.pos[self._device(name, JOINTS)]

    def write_digital(self, name: str, on: bool) -> None:
        self._device(name, ("gripper",))
        self.gripper_closed = bool(on)

    def step(self, dt: float) -> None:
        for j in JOINTS:
            t = self.target[j]
            if t is None:
                continue
            reach = self.speed[j] * dt
            err = t - self.pos[j]
            self.pos[j] = t if abs(err) <= reach else self.pos[j] + (reach if err > 0 else -reach)
        self.revision += 1


def arm_part(ctx: Any, module: str, config: Any) -> ArmPart:
    """The `module.arm` emulator: the joints start at their stow angles from YAML."""
    start = {j: float(d.params.get("stow", 0.0)) for j, d in config.devices.items()
             if j in JOINTS}
    return ArmPart(module, start)
