"""A fake `Phidget22` package for the Spatial and RCServo drivers (the autonomy's gimbal and
IMU, the backend's servo channels).

`install(monkeypatch)` puts it in `sys.modules` under the real module names, so the drivers'
own `from Phidget22.Devices.Spatial import Spatial` runs unchanged. The fake keeps Phidget22's
method names, refuses what the library refuses (settings before attach, targets outside
Min/MaxPosition, engaging without a target, `openWaitForAttachment` which would block the
tick) and calls the registered handlers the way libphidget22 does: from threads that are not
the test's (`on_library_thread`).
"""

from __future__ import annotations

import sys
import threading
import types
from collections.abc import Callable
from typing import Any

import pytest

EPHIDGET_OUTOFBOUNDS = 20
EPHIDGET_UNKNOWNVAL = 51
EPHIDGET_NOTATTACHED = 52
PUNK_DBL = 1e300


class FakePhidgetException(Exception):
    def __init__(self, code: int, description: str = "") -> None:
        super().__init__(f"{code}: {description}")
        self.code = code
        self.description = description
        self.details = description


class FakeLibrary:
    """Every channel object created through the fake package."""

    def __init__(self) -> None:
        self.created: list[FakeChannel] = []
        self.constructor_error: OSError | None = None

    def of(self, cls: type[FakeChannel], channel: int | None = None) -> Any:
        found = [c for c in self.created if isinstance(c, cls)
                 and (channel is None or c.channel == channel)]
        assert found, f"no {cls.__name__} {channel} created"
        return found[-1]


LIBRARY = FakeLibrary()


class FakeChannel:
    min_interval = 1
    max_interval = 1000

    def __init__(self) -> None:
        if LIBRARY.constructor_error is not None:
            raise LIBRARY.constructor_error
        LIBRARY.created.append(self)
        self.calls: list[str] = []
        self.handlers: dict[str, Callable[..., None]] = {}
        self.serial: int | None = None
        self.hub_port: int | None = None
        self.channel: int | None = None
        self.is_open = False
        self.attached = False
        self.close_count = 0
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
        self.is_open = True
        self.opened_on = threading.get_ident()

    def openWaitForAttachment(self, ms: int) -> None:
        raise AssertionError("openWaitForAttachment blocks the tick")

    def close(self) -> None:
        self.calls.append("close")
        self.close_count += 1
        self.is_open = False
        self.attached = False

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


def install(monkeypatch: pytest.MonkeyPatch) -> FakeLibrary:
    """Put the fake package in sys.modules under Phidget22's module names."""
    global LIBRARY
    LIBRARY = FakeLibrary()
    pkg = types.ModuleType("Phidget22")
    pkg.__path__ = []  # a package
    devices = types.ModuleType("Phidget22.Devices")
    devices.__path__ = []
    spatial = types.ModuleType("Phidget22.Devices.Spatial")
    spatial.Spatial = FakeSpatial  # type: ignore[attr-defined]
    rcservo = types.ModuleType("Phidget22.Devices.RCServo")
    rcservo.RCServo = FakeRCServo  # type: ignore[attr-defined]
    exc = types.ModuleType("Phidget22.PhidgetException")
    exc.PhidgetException = FakePhidgetException  # type: ignore[attr-defined]
    for name, mod in (("Phidget22", pkg), ("Phidget22.Devices", devices),
                      ("Phidget22.Devices.Spatial", spatial),
                      ("Phidget22.Devices.RCServo", rcservo),
                      ("Phidget22.PhidgetException", exc)):
        monkeypatch.setitem(sys.modules, name, mod)
    return LIBRARY
