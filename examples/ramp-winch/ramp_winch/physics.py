"""The winch's physics: a rope of `length` m wound at 0.2 m/s at full duty (ASSUMPTION); the
top switch closes when the load reaches the top. `ramp.emulators` entry `module.winch`."""

from __future__ import annotations

from typing import Any

SPEED_M_S = 0.2


class WinchPart:
    def __init__(self, module: str, length: float = 1.0) -> None:
        self.module = module
        self.out = length  # rope paid out, m
        self.duty = 0.0
        self.revision = 0

    def _own(self, name: str, device: str) -> None:
        if name != f"{self.module}.{device}":
            raise KeyError(name)

    def set_motor(self, name: str, duty: float) -> None:
        self._own(name, "motor")
        self.duty = duty

    def read_digital(self, name: str) -> bool:
        self._own(name, "top")
        return self.out <= 0.0

    def step(self, dt: float) -> None:
        self.out = max(0.0, self.out - self.duty * SPEED_M_S * dt)
        self.revision += 1


def winch_part(ctx: Any, module: str, config: Any) -> WinchPart:
    return WinchPart(module)
