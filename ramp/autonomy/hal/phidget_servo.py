"""`phidget` gimbal driver: two RC servos on a PhidgetAdvancedServo, through Phidget22 `RCServo`.

Each axis is one `RCServo` channel of the same board. Phidget22 works in "position units"
that it maps linearly onto pulse widths (`MinPosition..MaxPosition` onto
`MinPulseWidth..MaxPulseWidth`); on every attach this driver sets that mapping from
`autonomy.yaml` (`neutral_us`, `us_per_deg`, `reversed`, limits) so that one position unit is
one degree of the gimbal, and the controller's own velocity limit and acceleration (speed
ramping on) move the servo smoothly. A reversed axis is sent the negated angle.

Commands are recorded by the HAL and handed to the library from `tick` once the channel is
attached, and again after every re-attach (the board forgets them). Target positions go out
with `setTargetPosition_async` when the library has it, so the tick never waits for a USB
round trip; its completion, PositionChange and TargetPositionReached arrive as queued events.
A channel is engaged only once its target write has completed, since an RC servo jumps to
whatever target the controller holds at that moment.
"""

from __future__ import annotations

import logging
import math
import queue
from dataclasses import dataclass
from typing import Any

from ramp.autonomy.config import GimbalConfig, ServoConfig
from ramp.autonomy.hal.interfaces import PanTilt, Servo
from ramp.common import phidget22 as pc
from ramp.errors import DeviceError

log = logging.getLogger(__name__)

#: PositionChange events while moving: often enough to follow a sweep, few enough for USB.
POSITION_INTERVAL_MS = 20


@dataclass(frozen=True)
class RCServoApi:
    """The parts of Phidget22 this driver uses (names as in Phidget22)."""

    RCServo: Any
    PhidgetException: type[BaseException]


def load_phidget22() -> RCServoApi:
    from Phidget22.Devices.RCServo import RCServo
    from Phidget22.PhidgetException import PhidgetException

    return RCServoApi(RCServo=RCServo, PhidgetException=PhidgetException)


class PhidgetServo(Servo):
    """One axis; remembers what the controller has been told since its last attach."""

    def __init__(self, gimbal: PhidgetPanTilt, config: ServoConfig) -> None:
        super().__init__(gimbal.name, config)
        self.gimbal = gimbal
        self.handle: Any = None
        self.sign = -1.0 if config.reversed else 1.0
        self.sent: dict[str, Any] = {}  # what the library was given: key -> value
        self.has_target = False  # the controller holds a target (engaging is allowed)
        self.retry_at = -math.inf

    def to_units(self, deg: float) -> float:
        return self.sign * deg

    def to_deg(self, units: float) -> float:
        return self.sign * float(units)

    def where(self) -> str:
        return f"RCServo channel {self.config.channel}"

    # Commands are only recorded; the gimbal's tick writes them when attached.
    def _apply_target(self, deg: float) -> None:
        self.sent.pop("target", None)

    def _apply_velocity_limit(self, dps: float) -> None:
        self.sent.pop("velocity", None)

    def _apply_acceleration(self, dps2: float) -> None:
        self.sent.pop("acceleration", None)

    def _apply_engaged(self, on: bool) -> None:
        self.sent.pop("engaged", None)


class PhidgetPanTilt(PanTilt):
    driver_name = "phidget"

    def __init__(self, config: GimbalConfig, name: str = "gimbal", *,
                 api: RCServoApi | None = None) -> None:
        self._api = api
        self._queue: queue.SimpleQueue[pc.Event] = queue.SimpleQueue()
        super().__init__(config, name)
        self.error_counts: dict[int, int] = {}

    def _make_servo(self, config: ServoConfig) -> Servo:
        return PhidgetServo(self, config)

    @property
    def axes(self) -> tuple[PhidgetServo, PhidgetServo]:
        pan, tilt = self.pan, self.tilt
        assert isinstance(pan, PhidgetServo) and isinstance(tilt, PhidgetServo)
        return (pan, tilt)

    def where(self) -> str:
        serial = "any serial" if self.config.serial < 0 else f"serial {self.config.serial}"
        return f"PhidgetAdvancedServo ({serial})"

    # -- lifecycle --------------------------------------------------------------------------
    def _open(self, now: float) -> None:
        if self._api is None:
            try:
                self._api = pc.import_phidget22(load_phidget22)
            except pc.PhidgetUnavailable as exc:
                raise DeviceError(self.name, str(exc)) from exc.__cause__
        api = self._api
        q: queue.SimpleQueue[pc.Event] = queue.SimpleQueue()
        self._queue = q
        try:
            for idx, axis in enumerate(self.axes):
                axis.attached = False
                axis.position_deg = None
                axis.sent = {}
                axis.handle = ch = pc.construct(api.RCServo)
                pc.match(ch, self.config.serial, self.config.hub_port, axis.config.channel)
                pc.common_handlers(ch, q, idx)
                self._motion_handlers(ch, q, idx)
                ch.open()  # returns at once; the attach comes as an event
        except pc.PhidgetUnavailable as exc:
            self._close()
            raise DeviceError(self.name, str(exc)) from exc.__cause__
        except api.PhidgetException as exc:
            self._close()
            raise DeviceError(self.name, f"cannot open the {self.where()}: "
                              f"{pc.describe(exc)}") from exc

    @staticmethod
    def _motion_handlers(ch: Any, q: queue.SimpleQueue[pc.Event], idx: int) -> None:
        # These run on libphidget22's threads: enqueue and nothing else.
        def on_position(_ch: Any, position: Any) -> None:
            q.put(("position", idx, position))

        def on_reached(_ch: Any, position: Any) -> None:
            q.put(("reached", idx, position))

        ch.setOnPositionChangeHandler(on_position)
        ch.setOnTargetPositionReachedHandler(on_reached)

    def _tick(self, now: float, dt: float) -> None:
        axes = self.axes
        for event, idx, payload in pc.drain(self._queue):
            axis = axes[idx]
            if event == "position":
                if axis.engaged:
                    axis._report_position(axis.to_deg(payload))
            elif event == "reached":
                axis._report_reached(axis.to_deg(payload))
            elif event == "written":
                self._on_written(axis, payload, now)
            elif event == "attach":
                self._on_attach(axis)
            elif event == "detach":
                axis.attached = False
                axis.position_deg = None
                self._set_fault(DeviceError(self.name, f"{self.where()} {axis.where()} "
                                            "detached", axis.label))
            elif event == "error":
                self._on_error(axis, *payload)
        for axis in axes:
            if axis.attached:
                self._flush(axis, now)

    def _close(self) -> None:
        for axis in self.axes:
            ch, axis.handle = axis.handle, None
            axis.attached = False
            axis.position_deg = None
            pc.close_quietly(ch, f"{self.where()} {axis.where()}")

    # -- events -----------------------------------------------------------------------------
    def _on_attach(self, axis: PhidgetServo) -> None:
        api = self._api
        assert api is not None
        ch = axis.handle
        cfg = axis.config
        lo, hi = sorted((axis.to_units(cfg.min_deg), axis.to_units(cfg.max_deg)))
        try:
            pc.set_servo_range(ch, cfg.neutral_us, cfg.us_per_deg, lo, hi)
            ch.setDataInterval(pc.clamp_interval(ch, POSITION_INTERVAL_MS, axis.label))
        except api.PhidgetException as exc:
            self._set_fault(DeviceError(self.name, f"cannot configure {self.where()} "
                                        f"{axis.where()}: {pc.describe(exc)}", axis.label))
            return
        axis.attached = True
        axis.sent = {}  # the board forgot everything: write it all again
        axis.has_target = False
        axis.retry_at = -math.inf
        log.info("%s: %s %s (%s) attached", self.name, self.where(), axis.where(), axis.label)
        if self.attached:
            self._clear_fault()

    def _on_error(self, axis: PhidgetServo, code: Any, description: Any) -> None:
        key = int(code)
        self.error_counts[key] = self.error_counts.get(key, 0) + 1
        log.warning("%s: %s %s (%s): error event %s: %s", self.name, self.where(),
                    axis.where(), axis.label, key, description)

    def _on_written(self, axis: PhidgetServo, payload: tuple[float, int], now: float) -> None:
        units, code = payload
        if not code:
            axis.has_target = True
        elif axis.sent.get("target") == units:
            axis.sent.pop("target", None)
            axis.retry_at = now + pc.RETRY_S
            log.warning("%s: %s: setting target %g failed with code %s", self.name,
                        axis.label, axis.to_deg(units), code)

    # -- commands ---------------------------------------------------------------------------
    def _flush(self, axis: PhidgetServo, now: float) -> None:
        """Write what changed (or everything, after an attach), in the order the controller
        needs: motion limits, then the target, then engage."""
        if now < axis.retry_at:
            return
        api = self._api
        assert api is not None
        ch = axis.handle
        try:
            if axis.sent.get("acceleration") != axis.acceleration_dps2:
                ch.setAcceleration(_clamp(axis.acceleration_dps2, ch.getMinAcceleration(),
                                          ch.getMaxAcceleration()))
                axis.sent["acceleration"] = axis.acceleration_dps2
            if axis.sent.get("velocity") != axis.velocity_limit_dps:
                ch.setVelocityLimit(_clamp(axis.velocity_limit_dps, ch.getMinVelocityLimit(),
                                           ch.getMaxVelocityLimit()))
                axis.sent["velocity"] = axis.velocity_limit_dps
            if axis.target_deg is not None:
                units = axis.to_units(axis.target_deg)
                if axis.sent.get("target") != units:
                    self._send_target(axis, units)
            # Engage only once the controller holds a target: it jumps straight to it.
            if axis.sent.get("engaged") != axis.engaged and (
                    axis.has_target or not axis.engaged):
                ch.setEngaged(axis.engaged)
                axis.sent["engaged"] = axis.engaged
        except api.PhidgetException as exc:
            axis.retry_at = now + pc.RETRY_S
            log.warning("%s: %s: command failed, retrying: %s", self.name, axis.label,
                        pc.describe(exc))

    def _send_target(self, axis: PhidgetServo, units: float) -> None:
        q = self._queue
        idx = self.axes.index(axis)

        def on_done(code: int) -> None:
            q.put(("written", idx, (units, code)))  # library thread: enqueue only

        sent_async = pc.send_target(axis.handle, units, on_done)  # raises when refused
        axis.sent["target"] = units  # when async: in flight; a failure event clears it
        if not sent_async:
            axis.has_target = True


def _clamp(value: float, lo: Any, hi: Any) -> float:
    return min(max(value, float(lo)), float(hi))
