"""A fake `Phidget22` package for every driver on the vendor's package: the backend's
`phidget` bus (voltage, bridge and digital channels, RC servos) and the autonomy's Spatial
IMU and RCServo gimbal.

`install(monkeypatch)` puts it in `sys.modules` under the real module names, so the drivers'
own `from Phidget22.Devices.Spatial import Spatial` runs unchanged; `FakeBoard` instead hands
the backend driver its classes directly (`PhidgetApi`), one board per test. The fake keeps
Phidget22's method names, refuses what the library refuses (settings before attach, targets
outside Min/MaxPosition, engaging without a target, `openWaitForAttachment` which would block
the tick) and calls the registered handlers the way libphidget22 does: from threads that are
not the test's (`on_library_thread`).

`serve()` is the same fake for `python -m bench` (its real-driver `ramp run`, through
`bench.child supervisor --fake-phidget22`): a `LiveLibrary` whose own thread attaches every
opened channel and sends steady samples at each one's data interval, as libphidget22 does.
"""

from __future__ import annotations

import heapq
import sys
import threading
import time
import types
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ramp.hal.phidget import PhidgetApi

if TYPE_CHECKING:
    import pytest

EPHIDGET_OUTOFBOUNDS = 20
EPHIDGET_UNKNOWNVAL = 51
EPHIDGET_NOTATTACHED = 52
EEPHIDGET_SATURATION = 0x1009
PUNK_DBL = 1e300


class FakePhidgetException(Exception):
    def __init__(self, code: int, description: str = "") -> None:
        super().__init__(f"{code}: {description}")
        self.code = code
        self.description = description
        self.details = description


class FakeBridgeGain:
    # Phidget22's enum values (BridgeGain.py), deliberately not equal to the gains.
    BRIDGE_GAIN_1 = 1
    BRIDGE_GAIN_8 = 4
    BRIDGE_GAIN_16 = 5
    BRIDGE_GAIN_32 = 6
    BRIDGE_GAIN_64 = 7
    BRIDGE_GAIN_128 = 8


class FakeVoltageSensorType:
    SENSOR_TYPE_VOLTAGE = 0
    SENSOR_TYPE_1135 = 11350


class FakeLibrary:
    """Every channel object created through the fake package."""

    def __init__(self) -> None:
        self.created: list[FakeChannel] = []
        self.constructor_error: OSError | None = None
        self.fail_open: set[type] = set()  # open() of these classes raises

    def of(self, cls: type[FakeChannel], channel: int | None = None) -> Any:
        found = [c for c in self.created if isinstance(c, cls)
                 and (channel is None or c.channel == channel)]
        assert found, f"no {cls.__name__} {channel} created"
        return found[-1]

    def open_handles(self) -> list[FakeChannel]:
        return [c for c in self.created if c.is_open]

    def opened(self, ch: FakeChannel) -> None:
        """A channel was opened (the tests attach it themselves: `plug`)."""


LIBRARY = FakeLibrary()


class FakeChannel:
    """Phidget22 channel base: matching, handlers, open/close, attach bookkeeping."""

    min_interval = 1
    max_interval = 1000

    def __init__(self, library: FakeLibrary | None = None) -> None:
        library = library or LIBRARY
        if library.constructor_error is not None:
            raise library.constructor_error
        library.created.append(self)
        self.library = library
        self.calls: list[str] = []
        self.handlers: dict[str, Callable[..., None]] = {}
        self.serial: int | None = None
        self.hub_port: int | None = None
        self.channel: int | None = None
        self.label: str | None = None
        self.is_open = False
        self.attached = False
        self.close_count = 0
        self.close_raises = False
        self.open_raises = type(self) in library.fail_open
        self.data_interval: int | None = None
        self.handler_threads: set[int] = set()
        self.opened_on: int | None = None

    def setDeviceSerialNumber(self, n: int) -> None:
        self.calls.append("setDeviceSerialNumber")
        self.serial = n

    def setHubPort(self, n: int) -> None:
        self.calls.append("setHubPort")
        self.hub_port = n

    def setChannel(self, n: int) -> None:
        self.calls.append("setChannel")
        self.channel = n

    def setDeviceLabel(self, s: str) -> None:
        self.calls.append("setDeviceLabel")
        self.label = s

    def setOnAttachHandler(self, h: Callable[..., None]) -> None:
        self.calls.append("setOnAttachHandler")
        self.handlers["attach"] = h

    def setOnDetachHandler(self, h: Callable[..., None]) -> None:
        self.calls.append("setOnDetachHandler")
        self.handlers["detach"] = h

    def setOnErrorHandler(self, h: Callable[..., None]) -> None:
        self.calls.append("setOnErrorHandler")
        self.handlers["error"] = h

    def open(self) -> None:
        self.calls.append("open")
        if self.open_raises:
            raise FakePhidgetException(13, "invalid argument")
        self.is_open = True
        self.opened_on = threading.get_ident()
        self.library.opened(self)

    def openWaitForAttachment(self, ms: int) -> None:
        raise AssertionError("openWaitForAttachment blocks the tick")

    def close(self) -> None:
        self.calls.append("close")
        self.close_count += 1
        self.is_open = False
        self.attached = False
        if self.close_raises:
            raise FakePhidgetException(EPHIDGET_NOTATTACHED, "not attached")

    def getAttached(self) -> bool:
        return self.attached

    def need_attached(self) -> None:
        if not self.attached:
            raise FakePhidgetException(EPHIDGET_NOTATTACHED, "not attached")

    def getMinDataInterval(self) -> int:
        self.need_attached()
        return self.min_interval

    def getMaxDataInterval(self) -> int:
        self.need_attached()
        return self.max_interval

    def setDataInterval(self, ms: int) -> None:
        self.need_attached()
        assert isinstance(ms, int)
        if not self.min_interval <= ms <= self.max_interval:
            raise FakePhidgetException(EPHIDGET_OUTOFBOUNDS, "out of bounds")
        self.calls.append(f"setDataInterval({ms})")
        self.data_interval = ms

    # the library's side
    def fire(self, name: str, *args: Any) -> None:
        self.handler_threads.add(threading.get_ident())
        self.handlers[name](self, *args)

    def plug(self) -> None:
        assert self.is_open, "the library attaches only open channels"
        self.attached = True
        self.data_interval = None  # a re-attached board forgot its settings
        self.fire("attach")

    def unplug(self) -> None:
        self.attached = False
        self.fire("detach")


class FakeSpatial(FakeChannel):
    min_interval = 4

    def __init__(self) -> None:
        super().__init__()
        self.zeroed = 0

    def setOnSpatialDataHandler(self, h: Callable[..., None]) -> None:
        self.calls.append("setOnSpatialDataHandler")
        self.handlers["data"] = h

    def zeroGyro(self) -> None:
        self.need_attached()
        self.zeroed += 1

    def send(self, accel: list[float], gyro: list[float], mag: list[float],
             timestamp_ms: float) -> None:
        self.fire("data", list(accel), list(gyro), list(mag), timestamp_ms)


class FakeRCServo(FakeChannel):
    min_interval = 20

    def __init__(self) -> None:
        super().__init__()
        self.reset_settings()
        self.writes: list[tuple[str, Any]] = []
        self.pending: list[tuple[float, Callable[..., None]]] = []
        self.async_supported = True
        self.refuse_targets = 0  # the next n target writes fail (a USB hiccup)

    def reset_settings(self) -> None:
        self.min_pulse, self.max_pulse = 544.0, 2400.0
        self.min_pos, self.max_pos = 0.0, 180.0
        self.target: float | None = None
        self.engaged = False
        self.ramping = False
        self.velocity_limit = 1900.0
        self.acceleration = 3800.0

    def plug(self) -> None:
        self.reset_settings()
        super().plug()

    def __getattribute__(self, name: str) -> Any:
        if name == "setTargetPosition_async" and not object.__getattribute__(
                self, "async_supported"):
            raise AttributeError(name)
        return object.__getattribute__(self, name)

    def setOnPositionChangeHandler(self, h: Callable[..., None]) -> None:
        self.calls.append("setOnPositionChangeHandler")
        self.handlers["position"] = h

    def setOnTargetPositionReachedHandler(self, h: Callable[..., None]) -> None:
        self.calls.append("setOnTargetPositionReachedHandler")
        self.handlers["reached"] = h

    def getMinPulseWidthLimit(self) -> float:
        self.need_attached()
        return 500.0

    def getMaxPulseWidthLimit(self) -> float:
        self.need_attached()
        return 2500.0

    def setMinPulseWidth(self, us: float) -> None:
        self.need_attached()
        self.min_pulse = us
        self.writes.append(("min_pulse", us))

    def setMaxPulseWidth(self, us: float) -> None:
        self.need_attached()
        self.max_pulse = us
        self.writes.append(("max_pulse", us))

    def setMinPosition(self, p: float) -> None:
        self.need_attached()
        if p >= self.max_pos:
            raise FakePhidgetException(EPHIDGET_OUTOFBOUNDS, "min above max")
        self.min_pos = p
        self.writes.append(("min_pos", p))

    def setMaxPosition(self, p: float) -> None:
        self.need_attached()
        if p <= self.min_pos:
            raise FakePhidgetException(EPHIDGET_OUTOFBOUNDS, "max below min")
        self.max_pos = p
        self.writes.append(("max_pos", p))

    def setSpeedRampingState(self, on: bool) -> None:
        self.need_attached()
        self.ramping = on
        self.writes.append(("ramping", on))

    def getMinAcceleration(self) -> float:
        self.need_attached()
        return 1.0

    def getMaxAcceleration(self) -> float:
        self.need_attached()
        return 50000.0

    def getMinVelocityLimit(self) -> float:
        self.need_attached()
        return 0.0

    def getMaxVelocityLimit(self) -> float:
        self.need_attached()
        return 1000.0

    def setAcceleration(self, a: float) -> None:
        self.need_attached()
        self.acceleration = a
        self.writes.append(("acceleration", a))

    def setVelocityLimit(self, v: float) -> None:
        self.need_attached()
        self.velocity_limit = v
        self.writes.append(("velocity", v))

    def _check_target(self, p: float) -> None:
        self.need_attached()
        if self.refuse_targets:
            self.refuse_targets -= 1
            raise FakePhidgetException(EPHIDGET_NOTATTACHED, "busy")
        if not self.min_pos <= p <= self.max_pos:
            raise FakePhidgetException(EPHIDGET_OUTOFBOUNDS, "target out of bounds")

    def setTargetPosition(self, p: float) -> None:
        self._check_target(p)
        self.target = p
        self.writes.append(("target", p))

    def setTargetPosition_async(self, p: float, handler: Callable[..., None]) -> None:
        self._check_target(p)
        self.pending.append((p, handler))

    def complete(self, code: int = 0) -> None:
        """The library finishes the oldest async target write (call on a library thread)."""
        p, handler = self.pending.pop(0)
        if code == 0:
            self.target = p
            self.writes.append(("target", p))
        handler(self, code, "" if code == 0 else "failed")

    def getEngaged(self) -> bool:
        return self.engaged

    def setEngaged(self, on: bool) -> None:
        self.need_attached()
        if on and self.target is None:
            raise FakePhidgetException(EPHIDGET_UNKNOWNVAL, "no target")
        self.engaged = on
        self.writes.append(("engaged", on))


class FakeVoltageInput(FakeChannel):
    max_interval = 60000

    def __init__(self, library: FakeLibrary | None = None) -> None:
        super().__init__(library)
        self.trigger: float | None = None
        self.sensor_type: int | None = None

    def setOnVoltageChangeHandler(self, h: Callable[..., None]) -> None:
        self.calls.append("setOnVoltageChangeHandler")
        self.handlers["sample"] = h

    def setVoltageChangeTrigger(self, t: float) -> None:
        self.need_attached()
        self.trigger = t

    def setSensorType(self, t: int) -> None:
        self.need_attached()
        self.sensor_type = t

    def getVoltage(self) -> float:
        raise AssertionError("getVoltage is not used: samples come from events")


class FakeVoltageRatioInput(FakeChannel):
    min_interval = 8
    max_interval = 60000

    def __init__(self, library: FakeLibrary | None = None) -> None:
        super().__init__(library)
        self.trigger: float | None = None
        self.bridge_enabled = False
        self.gain: int | None = None

    def setOnVoltageRatioChangeHandler(self, h: Callable[..., None]) -> None:
        self.calls.append("setOnVoltageRatioChangeHandler")
        self.handlers["sample"] = h

    def setVoltageRatioChangeTrigger(self, t: float) -> None:
        self.need_attached()
        self.trigger = t

    def setBridgeEnabled(self, on: bool) -> None:
        self.need_attached()
        self.bridge_enabled = on

    def setBridgeGain(self, g: int) -> None:
        self.need_attached()
        self.gain = g


class FakeDigitalInput(FakeChannel):
    max_interval = 60000

    def __init__(self, library: FakeLibrary | None = None) -> None:
        super().__init__(library)
        self.state: bool | None = None  # None: the library has no value yet

    def setOnStateChangeHandler(self, h: Callable[..., None]) -> None:
        self.calls.append("setOnStateChangeHandler")
        self.handlers["sample"] = h

    def getState(self) -> bool:
        self.need_attached()
        if self.state is None:
            raise FakePhidgetException(EPHIDGET_UNKNOWNVAL, "unknown value")
        return self.state


class FakeDigitalOutput(FakeChannel):
    max_interval = 60000

    def __init__(self, library: FakeLibrary | None = None) -> None:
        super().__init__(library)
        self.writes: list[bool] = []

    def setState(self, on: bool) -> None:
        self.need_attached()
        self.writes.append(on)


class FakeAsyncDigitalOutput(FakeDigitalOutput):
    """Like the real class: setState_async returns at once, the result comes on a thread."""

    def __init__(self, library: FakeLibrary | None = None) -> None:
        super().__init__(library)
        self.pending: list[tuple[bool, Callable[..., None]]] = []

    def setState(self, on: bool) -> None:
        raise AssertionError("the blocking setState is not used when setState_async exists")

    def setState_async(self, on: bool, handler: Callable[..., None]) -> None:
        self.pending.append((on, handler))

    def complete(self, code: int = 0) -> None:
        on, handler = self.pending.pop(0)
        if code == 0:
            self.writes.append(on)
        handler(self, code, "" if code == 0 else "failed")


class FakeBoard(FakeLibrary):
    """A library of its own whose classes the backend driver takes injected (`api`)."""

    def __init__(self, dout: type[FakeDigitalOutput] = FakeDigitalOutput) -> None:
        super().__init__()
        self.api = PhidgetApi(
            VoltageInput=lambda: FakeVoltageInput(self),
            VoltageRatioInput=lambda: FakeVoltageRatioInput(self),
            DigitalInput=lambda: FakeDigitalInput(self),
            DigitalOutput=lambda: dout(self),
            PhidgetException=FakePhidgetException,
            BridgeGain=FakeBridgeGain,
            VoltageSensorType=FakeVoltageSensorType,
        )


def on_library_thread(fn: Callable[[], None]) -> None:
    """Run `fn` on another thread, as libphidget22 runs its callbacks."""
    errors: list[BaseException] = []

    def run() -> None:
        try:
            fn()
        except BaseException as exc:  # noqa: BLE001 - re-raised on the test thread
            errors.append(exc)

    t = threading.Thread(target=run)
    t.start()
    t.join(5.0)
    assert not t.is_alive()
    if errors:
        raise errors[0]


def modules() -> dict[str, types.ModuleType]:
    """The fake package's modules under Phidget22's module names."""
    pkg = types.ModuleType("Phidget22")
    pkg.__path__ = []  # a package
    devices = types.ModuleType("Phidget22.Devices")
    devices.__path__ = []
    out = {"Phidget22": pkg, "Phidget22.Devices": devices}
    for name, value in (("Phidget22.PhidgetException.PhidgetException", FakePhidgetException),
                        ("Phidget22.BridgeGain.BridgeGain", FakeBridgeGain),
                        ("Phidget22.VoltageSensorType.VoltageSensorType", FakeVoltageSensorType),
                        ("Phidget22.Devices.Spatial.Spatial", FakeSpatial),
                        ("Phidget22.Devices.RCServo.RCServo", FakeRCServo),
                        ("Phidget22.Devices.VoltageInput.VoltageInput", FakeVoltageInput),
                        ("Phidget22.Devices.VoltageRatioInput.VoltageRatioInput",
                         FakeVoltageRatioInput),
                        ("Phidget22.Devices.DigitalInput.DigitalInput", FakeDigitalInput),
                        ("Phidget22.Devices.DigitalOutput.DigitalOutput", FakeDigitalOutput)):
        module, attr = name.rsplit(".", 1)
        mod = out.setdefault(module, types.ModuleType(module))
        setattr(mod, attr, value)
    return out


def install(monkeypatch: pytest.MonkeyPatch) -> FakeLibrary:
    """Put the fake package in sys.modules under Phidget22's module names."""
    global LIBRARY
    LIBRARY = FakeLibrary()
    for name, mod in modules().items():
        monkeypatch.setitem(sys.modules, name, mod)
    return LIBRARY


# -- the live library (python -m bench) --------------------------------------------------------
class LiveLibrary(FakeLibrary):
    """Attaches every opened channel from a thread of its own, then sends each input's
    samples at its data interval (250 ms until one is set), calling the handlers from that
    thread as libphidget22 does. Readings are steady: `volts` per voltage-input channel
    (`default_volts` for the rest), `ratio` on every bridge."""

    def __init__(self, volts: dict[int, float], default_volts: float, ratio: float) -> None:
        super().__init__()
        self.volts, self.default_volts, self.ratio = volts, default_volts, ratio
        self._lock = threading.Lock()
        self._due: list[tuple[float, int, FakeChannel]] = []
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None

    def opened(self, ch: FakeChannel) -> None:
        self._schedule(ch, time.monotonic() + 0.01)

    def _schedule(self, ch: FakeChannel, at: float) -> None:
        with self._lock:
            heapq.heappush(self._due, (at, id(ch), ch))
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="phidget22-fake",
                                                daemon=True)
                self._thread.start()
        self._wake.set()

    def _run(self) -> None:
        while True:
            with self._lock:
                due = self._due[0][0] if self._due else None
            self._wake.wait(None if due is None else max(0.0, due - time.monotonic()))
            self._wake.clear()
            now = time.monotonic()
            while True:
                with self._lock:
                    if not self._due or self._due[0][0] > now:
                        break
                    _, _, ch = heapq.heappop(self._due)
                again = self._service(ch)
                if again is not None:
                    with self._lock:
                        heapq.heappush(self._due, (now + again, id(ch), ch))

    def _service(self, ch: FakeChannel) -> float | None:
        """Attach, then the next sample; seconds to the one after, None: stop."""
        if not ch.is_open:
            return None
        if not ch.attached:
            if isinstance(ch, FakeDigitalInput) and ch.state is None:
                ch.state = False
            ch.attached = True
            ch.fire("attach")
        if isinstance(ch, FakeVoltageInput):
            ch.fire("sample", self.volts.get(ch.channel or 0, self.default_volts))
        elif isinstance(ch, FakeVoltageRatioInput):
            ch.fire("sample", self.ratio)
        else:
            return None  # no events but on change, and nothing changes
        return (ch.data_interval or 250) / 1000.0


def serve(volts: dict[int, float], default_volts: float, ratio: float) -> LiveLibrary:
    """Put the fake package in sys.modules (for good: this process runs no tests) with a
    live library behind it."""
    global LIBRARY
    LIBRARY = LiveLibrary(volts, default_volts, ratio)
    sys.modules.update(modules())
    return LIBRARY
