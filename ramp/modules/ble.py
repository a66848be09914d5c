"""MARTE's Bucket Ladder Excavator module: the chain, the lift actuator and the bin's load cell.

Requests and get rows are thesis tables 5.5 and 5.6 (SPEC 2.1) plus three extensions:
`load.tare` (zero the load cell with the bin empty), the get row `lift.stalled` (1 while
the lift's stall fault is latched) and `lift.reset` (acknowledge it: nothing else clears it,
SPEC 2.2). YAML settings block `lift`: `tolerance` (hold band,
default 0.03), `hysteresis` (a move stops this close to its target, default 0.01),
`stall_time` (s, default 1.5) and `stall_min_change` (least progress at full speed within
`stall_time`, default 0.01); see ramp.modules.thompson_actuator.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ramp.api import (
    LOAD_CELL_FIELDS,
    MOTOR_FIELDS,
    AnalogInput,
    Block,
    BridgeInput,
    DeviceSpec,
    FloatParam,
    Function,
    IntParam,
    LoadCell,
    Module,
    Motor,
    MotorChannel,
    Property,
    Task,
)
from ramp.modules.bucket_ladder import BucketLadder
from ramp.modules.thompson_actuator import LIFT_FIELDS, POT_FIELDS, ThompsonActuator


class BleModule(Module):
    """The BLE: `lift.vel/extend/retract/pos`, `chain.vel`, `load.tare`."""

    devices: ClassVar[dict[str, DeviceSpec]] = {
        "chain_left": DeviceSpec("motor", MOTOR_FIELDS, "bucket ladder chain, left"),
        "chain_right": DeviceSpec("motor", MOTOR_FIELDS, "bucket ladder chain, right"),
        "lift_motor": DeviceSpec("motor", MOTOR_FIELDS, "lift linear actuator"),
        "lift_pot": DeviceSpec("analog_in", POT_FIELDS, "lift feedback potentiometer"),
        "load_cell": DeviceSpec("bridge_in", LOAD_CELL_FIELDS, "bin load cell"),
    }
    settings: ClassVar[dict[str, Block]] = {"lift": LIFT_FIELDS}

    def __init__(self, name: str, devices: Mapping[str, Any],
                 settings: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        super().__init__(name)
        left, right, lift_m = (Motor.from_params(*self.device(devices, n, MotorChannel))
                               for n in ("chain_left", "chain_right", "lift_motor"))
        self.chain = BucketLadder(left, right)
        pot, pot_params = self.device(devices, "lift_pot", AnalogInput)
        self.lift = ThompsonActuator.from_params(lift_m, pot, pot_params,
                                                 self.setting(settings, "lift"))
        self.load = LoadCell.from_params(*self.device(devices, "load_cell", BridgeInput))

        speed = IntParam(-100, 100)
        self.add(Function("lift", "vel", (speed,), self.lift.vel, "motion",
                          "lift velocity in %; + extends"))
        self.add(Function("lift", "extend", (), self.lift.extend, "motion",
                          "extend at full speed to the end"))
        self.add(Function("lift", "retract", (), self.lift.retract, "motion",
                          "retract at full speed to the end"))
        self.add(Function("lift", "pos", (FloatParam(0.0, 1.0),), self.lift.move_to, "motion",
                          "move to a position and hold it"))
        self.add(Function("chain", "vel", (speed,), self.chain.vel, "motion",
                          "bucket ladder chain velocity in %"))
        self.add(Function("load", "tare", (), self.load.tare, "state",
                          "zero the load cell"))

        self.prop(Property("lift", "vel", "int", lambda: self.lift.velocity))
        self.prop(Property("lift", "pos", "float", lambda: self.lift.position))
        self.prop(Property("chain", "vel", "int", lambda: self.chain.velocity))
        self.prop(Property("load", "kg", "float", lambda: self.load.kg, "kg"))
        self.latched("lift", self.lift.latch, "stalled")

    def stop(self) -> None:
        """Lift and chain to 0, any move cancelled (a latched lift stall stays latched)."""
        self.lift.stop()
        self.chain.stop()

    def is_moving(self) -> bool:
        return self.lift.is_moving() or self.chain.is_moving()

    def tasks(self) -> list[Task]:
        """The lift controller at 50 Hz: 0.002 of stroke per tick at full speed (10 s
        stroke), far inside the 0.01 stop band."""
        return [Task("lift", 50.0, self.lift.tick)]
