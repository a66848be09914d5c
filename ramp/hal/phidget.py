"""`phidget` driver: one Phidget22 board (InterfaceKit 8/8/8, the SBC's own kit, PhidgetBridge).

Phidget22 is callback-driven: libphidget22 attaches channels and delivers samples on its own
threads. Those threads must never touch supervisor state, so every handler here does one thing,
put an event on a `queue.SimpleQueue`, and the bus's `tick` drains the queue on the scheduler's
thread. Nothing waits for the hardware: `open()` of a Phidget22 channel returns at once, the
attach arrives later as an event, and `ready()` turns True when every channel has attached
and every input has delivered its first sample. A detach, or a board that does not show up
within `attach_timeout`, is a DeviceError from `tick`; the supervisor then closes the bus and
retries opening it about once a second (SPEC 2.2, hot plug).

The vendor package is an optional extra (`pip install 'ramp[phidget]'`) that needs a native
library, so it is imported only when a bus opens, and the Phidget22 classes can be injected
(`api=`) so the tests run with fakes.
"""

from __future__ import annotations

import logging
import math
import queue
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from ramp.common import phidget22 as pc
from ramp.errors import ConfigError, DeviceError
from ramp.hal.interfaces import (
    AnalogInput,
    BridgeInput,
    Bus,
    DigitalInput,
    DigitalOutput,
    ServoChannel,
)
from ramp.schema import Field

log = logging.getLogger(__name__)

INSTALL_HINT = pc.INSTALL_HINT

#: Gains the PhidgetBridge 1046 offers; Phidget22 names them BridgeGain.BRIDGE_GAIN_<n>.
BRIDGE_GAINS = (1, 8, 16, 32, 64, 128)

#: Seconds between retries of a digital-output write that the library refused.
WRITE_RETRY_S = 0.1


@dataclass(frozen=True)
class PhidgetApi:
    """The parts of the Phidget22 package this driver uses (names as in Phidget22)."""

    VoltageInput: Callable[[], Any]
    VoltageRatioInput: Callable[[], Any]
    DigitalInput: Callable[[], Any]
    DigitalOutput: Callable[[], Any]
    PhidgetException: type[BaseException]
    BridgeGain: Any  # has BRIDGE_GAIN_1 ... BRIDGE_GAIN_128
    VoltageSensorType: Any = None  # has SENSOR_TYPE_VOLTAGE; None leaves the default
    RCServo: Callable[[], Any] | None = None  # servo channels; None: this api has none


def load_phidget22() -> PhidgetApi:
    """Import the real Phidget22 classes (ImportError when the package is absent)."""
    from Phidget22.BridgeGain import BridgeGain
    from Phidget22.Devices.DigitalInput import DigitalInput as PhDigitalInput
    from Phidget22.Devices.DigitalOutput import DigitalOutput as PhDigitalOutput
    from Phidget22.Devices.RCServo import RCServo
    from Phidget22.Devices.VoltageInput import VoltageInput
    from Phidget22.Devices.VoltageRatioInput import VoltageRatioInput
    from Phidget22.PhidgetException import PhidgetException
    from Phidget22.VoltageSensorType import VoltageSensorType

    return PhidgetApi(
        VoltageInput=VoltageInput,
        VoltageRatioInput=VoltageRatioInput,
        DigitalInput=PhDigitalInput,
        DigitalOutput=PhDigitalOutput,
        PhidgetException=PhidgetException,
        BridgeGain=BridgeGain,
        VoltageSensorType=VoltageSensorType,
        RCServo=RCServo,
    )


# -- events -----------------------------------------------------------------------------------
# Handlers run on libphidget22's threads and only ever put one of these tuples on the queue:
# (event, slot index, payload).
# The first three are the shared adapter's (`ramp.common.phidget22.common_handlers`).
_ATTACH, _DETACH, _ERROR, _SAMPLE, _WRITTEN = "attach", "detach", "error", "sample", "written"
Event = tuple[str, int, Any]

#: Phidget22 class per HAL kind.
_API_CLASS = {
    "analog_in": "VoltageInput",
    "bridge_in": "VoltageRatioInput",
    "digital_in": "DigitalInput",
    "digital_out": "DigitalOutput",
    "servo": "RCServo",
}
#: The widest a servo's position range is mapped (degrees each side of neutral).
SERVO_SPAN_DEG = 180.0


@dataclass(eq=False)
class _Slot:
    """One physical channel of the board, shared by every HAL channel that names it."""

    kind: str
    channel: int
    gain: int = 128
    labels: list[str] = field(default_factory=list)
    handle: Any = None  # the Phidget22 channel object while the bus is open
    attached: bool = False
    value: float | bool | None = None  # newest sample; None until the first one
    heard: bool = False  # a sample or an error event arrived since open
    error_code: int | None = None  # last error event, cleared by the next sample
    output: DigitalOutput | None = None  # digital out: its channel holds the state commanded
    servo: ServoChannel | None = None  # servo: its channel holds the target commanded
    servo_spec: tuple[float, float, float] = (1500.0, 10.0, 1.0)  # neutral_us, us/deg, sign
    sent_servo: tuple[float, float] | None = None  # servo: (units, deg/s) last handed over
    sent: bool | None = None  # digital out: the state last handed to the library
    retry_at: float = -math.inf

    @property
    def is_input(self) -> bool:
        return self.kind not in ("digital_out", "servo")

    @property
    def want(self) -> bool:
        """Digital out: the state its channel is commanded."""
        return self.output is not None and self.output.state

    def where(self) -> str:
        return f"{self.kind} channel {self.channel}"

    def who(self) -> str:
        return "/".join(self.labels)


# -- HAL channels -----------------------------------------------------------------------------
class _Analog(AnalogInput):
    def __init__(self, bus: PhidgetBus, label: str, slot: _Slot) -> None:
        super().__init__(bus, label)
        self._slot = slot

    def read(self) -> float:
        v = self._slot.value
        return math.nan if v is None else float(v)


class _Bridge(BridgeInput):
    def __init__(self, bus: PhidgetBus, label: str, slot: _Slot) -> None:
        super().__init__(bus, label)
        self._slot = slot

    def read(self) -> float:
        v = self._slot.value
        return math.nan if v is None else float(v)


class _DigitalIn(DigitalInput):
    def __init__(self, bus: PhidgetBus, label: str, slot: _Slot) -> None:
        super().__init__(bus, label)
        self._slot = slot

    def read(self) -> bool:
        return bool(self._slot.value)


class _Servo(ServoChannel):
    def __init__(self, bus: PhidgetBus, label: str, slot: _Slot) -> None:
        super().__init__(bus, label)
        self._slot = slot
        slot.servo = self  # the bus's tick hands its target to the library when attached

    def read(self) -> float:
        v = self._slot.value
        self.position = math.nan if v is None else float(v)
        return self.position


class _DigitalOut(DigitalOutput):
    def __init__(self, bus: PhidgetBus, label: str, slot: _Slot) -> None:
        super().__init__(bus, label)
        slot.output = self  # the bus's tick hands its state to the library when attached


_HAL_CLASS: dict[str, type] = {
    "analog_in": _Analog,
    "bridge_in": _Bridge,
    "digital_in": _DigitalIn,
    "digital_out": _DigitalOut,
    "servo": _Servo,
}


class PhidgetBus(Bus):
    """One Phidget board, matched by serial number (and hub port, label)."""

    driver_name = "phidget"
    fields: ClassVar[dict[str, Field]] = {
        "serial": Field(int, -1, lo=-1, hi=pc.MAX_SERIAL,
                        what="a Phidget serial number or -1 for any"),
        "hub_port": Field(int, -1, lo=-1, hi=pc.MAX_HUB_PORT,
                          what="a VINT hub port or -1 for any"),
        "label": Field(str, ""),
        "data_interval": Field(float, 0.02, lo=0.001, hi=60.0, what="a sample interval in s"),
        "attach_timeout": Field(float, 2.0, lo=0.05, hi=60.0, what="a time in s"),
    }
    channel_fields: ClassVar[dict[str, dict[str, Field]]] = {
        "analog_in": {"channel": Field(int, lo=0, hi=7, what="an analog input")},
        "digital_in": {"channel": Field(int, lo=0, hi=7, what="a digital input")},
        "digital_out": {"channel": Field(int, lo=0, hi=7, what="a digital output")},
        "bridge_in": {
            "channel": Field(int, lo=0, hi=3, what="a bridge input"),
            "gain": Field(int, 128, choices=BRIDGE_GAINS, what="a bridge gain"),
        },
        # An RC servo on a Phidget servo controller (RCServo): degrees map linearly onto the
        # pulse, `neutral_us` at 0 deg, `us_per_deg` per degree, negated when `reversed`.
        "servo": {
            "channel": Field(int, lo=0, hi=15, what="an RC servo channel"),
            "neutral_us": Field(float, 1500.0, lo=500.0, hi=2500.0, what="a pulse width in us"),
            "us_per_deg": Field(float, 10.0, lo=1.0, hi=50.0, what="microseconds per degree"),
            "reversed": Field(bool, False),
        },
    }

    def __init__(
        self, name: str, params: Mapping[str, Any], api: PhidgetApi | None = None
    ) -> None:
        super().__init__(name, params)
        cfg = self.check_params(params)
        self.serial: int = cfg["serial"]
        self.hub_port: int = cfg["hub_port"]
        self.label: str = cfg["label"]
        self.data_interval: float = cfg["data_interval"]
        self.attach_timeout: float = cfg["attach_timeout"]
        self._api = api
        self._api_error: DeviceError | None = None  # the native library failed to load
        self._slots: list[_Slot] = []
        self._queue: queue.SimpleQueue[Event] = queue.SimpleQueue()
        self._opened_at = 0.0
        #: Some channel needs the per-channel pass of `_tick` (attaching, not heard from, an
        #: output not yet as commanded); idle ticks skip it.
        self._care = True
        #: Open, past `attach_timeout`, and no channel attached: the board is not plugged in.
        self._waiting = False
        #: Error events seen, per Phidget22 error-event code (for health reports and tests).
        self.error_counts: dict[int, int] = {}

    # -- channels ---------------------------------------------------------------------------
    def _make_channel(self, kind: str, label: str, spec: dict[str, Any]) -> Any:
        channel = spec["channel"]
        gain = spec.get("gain", 128)
        slot = next((s for s in self._slots if s.kind == kind and s.channel == channel), None)
        if slot is None:
            slot = _Slot(kind=kind, channel=channel, gain=gain)
            self._slots.append(slot)
        elif kind in ("digital_out", "servo"):
            raise ConfigError(
                f"{kind} channel {channel} is already driven by {slot.who()}", key=label)
        elif kind == "bridge_in" and slot.gain != gain:
            raise ConfigError(
                f"bridge_in channel {channel} already uses gain {slot.gain}", key=label)
        if kind == "servo":
            slot.servo_spec = (spec["neutral_us"], spec["us_per_deg"],
                               -1.0 if spec["reversed"] else 1.0)
        slot.labels.append(label)
        return _HAL_CLASS[kind](self, label, slot)

    # -- lifecycle --------------------------------------------------------------------------
    def _open(self, now: float) -> None:
        api = self._load_api()
        # A fresh queue per open: events still arriving from the handles of a previous open
        # land in the old queue, which nobody reads any more.
        q: queue.SimpleQueue[Event] = queue.SimpleQueue()
        self._queue = q
        self._opened_at = now
        self._care = True
        self._waiting = False
        for slot in self._slots:
            slot.attached = False
            slot.value = None
            slot.heard = False
            slot.error_code = None
            slot.sent = None
            slot.retry_at = -math.inf
        try:
            for idx, slot in enumerate(self._slots):
                slot.handle = self._create(api, slot)
                self._setup(slot.handle, slot, idx, q)
                slot.handle.open()  # returns at once; the attach comes as an event
        except DeviceError:
            self._close()
            raise
        except api.PhidgetException as exc:
            self._close()
            raise DeviceError(self.name, f"cannot open the Phidget channels: {pc.describe(exc)}"
                              ) from exc

    def _load_api(self) -> PhidgetApi:
        if self._api_error is not None:
            raise DeviceError(self.name, self._api_error.detail) from self._api_error.__cause__
        if self._api is None:
            try:
                self._api = load_phidget22()
            except ImportError as exc:
                raise DeviceError(
                    self.name, f"the Phidget22 package is not installed; {INSTALL_HINT}"
                ) from exc
            except OSError as exc:  # today the package loads its library lazily; be safe
                raise DeviceError(
                    self.name, f"the Phidget22 native library cannot be loaded: {exc}; "
                    f"{INSTALL_HINT}"
                ) from exc
        return self._api

    def _create(self, api: PhidgetApi, slot: _Slot) -> Any:
        try:
            return getattr(api, _API_CLASS[slot.kind])()
        except OSError as exc:
            # Constructors load libphidget22 (which needs libusb-1.0); when that fails it will
            # fail the same way at every retry, and each attempt makes the library print a
            # traceback from __del__, so remember it instead of retrying every second.
            self._api_error = DeviceError(
                self.name, f"the Phidget22 native library cannot be loaded: {exc}; "
                f"{INSTALL_HINT}; then restart ramp"
            )
            raise self._api_error from exc

    def _setup(self, ch: Any, slot: _Slot, idx: int, q: queue.SimpleQueue[Event]) -> None:
        """Matching and handlers, all before `open()` as Phidget22 requires (the shared
        adapter's: its attach, detach and error events are this driver's)."""
        pc.match(ch, self.serial, self.hub_port, slot.channel)
        if self.label:
            ch.setDeviceLabel(self.label)
        pc.common_handlers(ch, q, idx)

        # Runs on libphidget22's threads: put an event on the queue and nothing else.
        def on_sample(_ch: Any, value: Any) -> None:
            q.put((_SAMPLE, idx, value))

        if slot.kind == "analog_in":
            ch.setOnVoltageChangeHandler(on_sample)
        elif slot.kind == "bridge_in":
            ch.setOnVoltageRatioChangeHandler(on_sample)
        elif slot.kind == "digital_in":
            ch.setOnStateChangeHandler(on_sample)
        elif slot.kind == "servo":
            ch.setOnPositionChangeHandler(on_sample)

    def _tick(self, now: float, dt: float) -> None:
        # Only what is queued now: a library thread that keeps producing cannot hold the tick.
        for _ in range(self._queue.qsize()):
            try:
                event, idx, payload = self._queue.get_nowait()
            except queue.Empty:
                break
            self._handle(self._slots[idx], event, payload, now)
        if not self._care:
            return  # every channel attached and heard, every output as commanded
        care = False
        for idx, slot in enumerate(self._slots):
            if slot.kind == "digital_in" and slot.attached and not slot.heard:
                self._seed(slot)
                care = care or not slot.heard
            elif slot.kind == "digital_out":
                self._flush(slot, idx, now)
                care = care or slot.sent != slot.want
            elif slot.kind == "servo":
                self._flush_servo(slot, idx, now)
                care = care or slot.sent_servo != _servo_want(slot)
        ready = self.ready()
        if not ready and now - self._opened_at > self.attach_timeout:
            if any(s.attached for s in self._slots):
                raise self._timeout_error()  # the board is there: a wrong channel, no data
            # No board at all: the library attaches the open channels by itself when one is
            # plugged in, so waiting is all there is to do (re-opening every few seconds only
            # made the bus flap between "back" and "fault"; issue 19.8).
            self._waiting = True
        self._care = care or not ready

    def _output_changed(self, ch: DigitalOutput) -> None:
        self._care = True  # the tick hands the new state to the library

    def _servo_changed(self, ch: ServoChannel) -> None:
        self._care = True  # the tick hands the new target to the library

    def _handle(self, slot: _Slot, event: str, payload: Any, now: float) -> None:
        if event != _SAMPLE or not slot.heard:
            self._care = True  # something to look at in this tick's per-channel pass
        if event == _SAMPLE:
            if slot.kind == "bridge_in":
                slot.value = float(payload) * 1000.0  # V/V -> mV/V
            elif slot.kind == "servo":
                slot.value = slot.servo_spec[2] * float(payload)  # units -> degrees
                if slot.servo is not None:
                    slot.servo.position = slot.value
            elif slot.kind == "digital_in":
                slot.value = bool(payload)
            else:
                slot.value = float(payload)
            slot.heard = True
            slot.error_code = None
        elif event == _ATTACH:
            slot.attached = True
            self._configure(slot)
            slot.sent = None  # re-write the output state on every attach
            slot.sent_servo = None
            slot.retry_at = -math.inf
        elif event == _DETACH:
            slot.attached = False
            raise DeviceError(self.name, f"Phidget {slot.where()} detached", slot.who())
        elif event == _ERROR:
            code, description = payload
            key = int(code)
            slot.heard = True  # a saturated input sends errors, not samples: still alive
            self.error_counts[key] = self.error_counts.get(key, 0) + 1
            if slot.error_code != key:  # once per condition, not once per sample interval
                slot.error_code = key
                log.warning("bus %s: Phidget %s (%s): error event %s: %s",
                            self.name, slot.where(), slot.who(), key, description)
        elif event == _WRITTEN and slot.kind == "servo":
            want, code = payload
            if code and slot.sent_servo == want:
                slot.sent_servo = None
                slot.retry_at = now + WRITE_RETRY_S
                log.warning("bus %s: Phidget %s (%s): target %s failed with code %s",
                            self.name, slot.where(), slot.who(), want[0], code)
            elif not code:
                self._engage(slot)
        elif event == _WRITTEN:
            state, code = payload
            if code and slot.sent == state:
                slot.sent = None
                slot.retry_at = now + WRITE_RETRY_S
                log.warning("bus %s: Phidget %s (%s): writing %s failed with code %s",
                            self.name, slot.where(), slot.who(), state, code)

    def _configure(self, slot: _Slot) -> None:
        """Per-attach settings; Phidget22 accepts most of them only on an attached channel."""
        api = self._api
        assert api is not None
        ch = slot.handle
        try:
            if slot.kind == "analog_in":
                if api.VoltageSensorType is not None:
                    ch.setSensorType(api.VoltageSensorType.SENSOR_TYPE_VOLTAGE)
                ch.setDataInterval(self._interval_ms(ch))
                ch.setVoltageChangeTrigger(0.0)  # an event every interval, changed or not
            elif slot.kind == "servo":
                neutral, per_deg, _ = slot.servo_spec
                lo = max(-SERVO_SPAN_DEG, (ch.getMinPulseWidthLimit() - neutral) / per_deg)
                hi = min(SERVO_SPAN_DEG, (ch.getMaxPulseWidthLimit() - neutral) / per_deg)
                pc.set_servo_range(ch, neutral, per_deg, lo, hi)
            elif slot.kind == "bridge_in":
                ch.setBridgeGain(getattr(api.BridgeGain, f"BRIDGE_GAIN_{slot.gain}"))
                ch.setBridgeEnabled(True)
                ch.setDataInterval(self._interval_ms(ch))
                ch.setVoltageRatioChangeTrigger(0.0)
        except api.PhidgetException as exc:
            raise DeviceError(
                self.name, f"cannot configure Phidget {slot.where()}: {pc.describe(exc)}",
                slot.who(),
            ) from exc

    def _interval_ms(self, ch: Any) -> int:
        """`data_interval` in ms, clamped to what this channel supports."""
        ms = int(round(self.data_interval * 1000.0))
        lo, hi = int(ch.getMinDataInterval()), int(ch.getMaxDataInterval())
        clamped = min(max(ms, lo), hi)
        if clamped != ms:
            log.info("bus %s: data_interval %d ms clamped to %d ms", self.name, ms, clamped)
        return clamped

    def _seed(self, slot: _Slot) -> None:
        """A digital input's state right after attach: it sends events only on change, so
        one that never changes would never report. Analog and bridge inputs are not polled:
        with a change trigger of 0 they send an event every interval."""
        api = self._api
        assert api is not None
        try:
            v = slot.handle.getState()
        except api.PhidgetException:
            return  # no value yet (EPHIDGET_UNKNOWNVAL); try again next tick
        slot.value = bool(v)
        slot.heard = True

    def _flush(self, slot: _Slot, idx: int, now: float) -> None:
        """Hand the commanded output state to the library when attached and changed."""
        if not slot.attached or slot.sent == slot.want or now < slot.retry_at:
            return
        api = self._api
        assert api is not None
        state = slot.want
        ch = slot.handle
        slot.sent = state
        set_async = getattr(ch, "setState_async", None)
        try:
            if set_async is not None:
                q = self._queue

                def on_done(_ch: Any, code: Any, _details: Any = "") -> None:
                    q.put((_WRITTEN, idx, (state, int(code))))  # library thread: queue only

                set_async(state, on_done)
            else:
                ch.setState(state)
        except api.PhidgetException as exc:
            slot.sent = None
            slot.retry_at = now + WRITE_RETRY_S
            log.warning("bus %s: Phidget %s (%s): writing %s failed: %s",
                        self.name, slot.where(), slot.who(), state, pc.describe(exc))

    def _flush_servo(self, slot: _Slot, idx: int, now: float) -> None:
        """Hand a servo's target and speed limit to the library when attached and changed;
        engage it once the controller holds the target (an RC servo jumps to whatever target
        the controller holds when engaged)."""
        want = _servo_want(slot)
        if not slot.attached or want is None or slot.sent_servo == want or now < slot.retry_at:
            return
        api = self._api
        assert api is not None
        ch = slot.handle
        q = self._queue

        def on_done(code: int) -> None:
            q.put((_WRITTEN, idx, (want, code)))  # library thread: queue only

        try:
            ch.setVelocityLimit(min(max(want[1], float(ch.getMinVelocityLimit())),
                                    float(ch.getMaxVelocityLimit())))
            sent_async = pc.send_target(ch, want[0], on_done)
            slot.sent_servo = want
            if not sent_async:
                self._engage(slot)
        except api.PhidgetException as exc:
            slot.sent_servo = None
            slot.retry_at = now + WRITE_RETRY_S
            log.warning("bus %s: Phidget %s (%s): target %s failed: %s", self.name,
                        slot.where(), slot.who(), want[0], pc.describe(exc))

    def _engage(self, slot: _Slot) -> None:
        api = self._api
        assert api is not None
        try:
            if not slot.handle.getEngaged():
                slot.handle.setEngaged(True)
        except api.PhidgetException as exc:
            log.warning("bus %s: Phidget %s (%s): engaging failed: %s", self.name,
                        slot.where(), slot.who(), pc.describe(exc))

    def _timeout_error(self) -> DeviceError:
        missing = [s for s in self._slots if not s.attached]
        serial = "any serial" if self.serial < 0 else f"serial {self.serial}"
        if missing:
            names = " ".join(f"{s.kind} {s.channel}" for s in missing)
            return DeviceError(
                self.name,
                f"Phidget {serial} not attached within {self.attach_timeout:g} s: {names}"
                " - check the USB cable and the serial number",
                missing[0].who(),
            )
        silent = [s for s in self._slots if s.is_input and not s.heard]
        names = " ".join(f"{s.kind} {s.channel}" for s in silent)
        return DeviceError(
            self.name,
            f"Phidget {serial} attached but sent no data within {self.attach_timeout:g} s: "
            f"{names}",
            silent[0].who() if silent else "",
        )

    def waiting(self) -> str:
        """Why an open bus is not ready, once its board has been absent past
        `attach_timeout` (the library attaches it when it is plugged in)."""
        if not (self.is_open and self._waiting) or any(s.attached for s in self._slots):
            return ""
        serial = "any serial" if self.serial < 0 else f"serial {self.serial}"
        names = " ".join(f"{s.kind} {s.channel}" for s in self._slots)
        return (f"waiting for its board: Phidget {serial} ({names}) is not attached - "
                "check the USB cable and the serial number")

    def ready(self) -> bool:
        """Open, every channel attached, and every input heard from (a sample, or an error
        event such as saturation: then `read()` gives NaN until a sample comes)."""
        return self.is_open and all(s.attached and (s.heard or not s.is_input)
                                    for s in self._slots)

    def _stop_motors(self) -> None:
        """A Phidget board drives no motors; its servos hold where they are, now (the HAL set
        their targets to the positions they report)."""
        for idx, slot in enumerate(self._slots):
            if slot.kind == "servo" and slot.handle is not None:
                self._flush_servo(slot, idx, math.inf)

    def _close(self) -> None:
        for slot in self._slots:
            ch, slot.handle = slot.handle, None
            slot.attached = False
            if ch is None:
                continue
            try:
                ch.close()
            except Exception as exc:  # noqa: BLE001 - closing must always finish
                log.debug("bus %s: closing Phidget %s: %s", self.name, slot.where(), exc)


def _servo_want(slot: _Slot) -> tuple[float, float] | None:
    """What a servo slot should hold: (target in the library's units, speed limit)."""
    ch = slot.servo
    if ch is None or ch.target is None:
        return None
    return (slot.servo_spec[2] * ch.target, ch.speed_dps)
