"""The one Phidget22 adapter: what every driver on the vendor's package shares (the backend's
`phidget` bus, the autonomy's Spatial IMU and RCServo gimbal).

Phidget22 is callback-driven: libphidget22 attaches channels and delivers data on its own
threads. Those threads must never touch the autonomy's state, so every handler does one thing,
put an event on a `queue.SimpleQueue`, and the device's `tick` drains that queue on the
scheduler's thread. `open()` of a Phidget22 channel returns at once; the attach arrives later
as an event (never `openWaitForAttachment`, which blocks). When the USB cable comes back the
library re-attaches the same open channel by itself, so a detach is a fault that clears on the
next attach, with no re-open.

The vendor package is an optional extra (`pip install 'ramp[phidget]'`) that needs a native
library: it is imported when a device opens, not when this module is imported.
"""

from __future__ import annotations

import logging
import queue
from collections.abc import Callable
from typing import Any

log = logging.getLogger("ramp.phidget22")

INSTALL_HINT = "install it with: pip install 'ramp[phidget]' and apt-get install libusb-1.0-0"

#: libphidget22's "unknown double" (PUNK_DBL): a reading the board does not have.
PUNK_DBL = 1e300

#: The largest serial number and VINT hub port Phidget22 takes: it keeps both in a C int (a
#: larger serial was cut to 32 bits by ctypes and matched another board), and a hub has
#: ports 0-5.
MAX_SERIAL = 2**31 - 1
MAX_HUB_PORT = 5

#: Seconds between retries of a command the library refused.
RETRY_S = 0.1

Event = tuple[str, Any, Any]  # (event, which channel, payload)


class PhidgetUnavailable(Exception):
    """The Phidget22 package or its native library cannot be loaded; the text says how to
    install it. Callers turn it into their own device error (`DeviceError(name, str(exc))`),
    since this leaf imports nothing of RAMP."""


def import_phidget22(load: Callable[[], Any]) -> Any:
    """Run `load` (which imports Phidget22 classes); a missing package or native library is
    PhidgetUnavailable (its cause the ImportError or OSError)."""
    try:
        return load()
    except ImportError as exc:
        raise PhidgetUnavailable(f"the Phidget22 package is not installed; {INSTALL_HINT}"
                                 ) from exc
    except OSError as exc:
        raise PhidgetUnavailable(f"the Phidget22 native library cannot be loaded: {exc}; "
                                 f"{INSTALL_HINT}") from exc


def construct(cls: Callable[[], Any]) -> Any:
    """A Phidget22 channel object. Constructors load libphidget22 (which needs libusb-1.0);
    when that fails it is PhidgetUnavailable."""
    try:
        return cls()
    except OSError as exc:
        raise PhidgetUnavailable(f"the Phidget22 native library cannot be loaded: {exc}; "
                                 f"{INSTALL_HINT}") from exc


def match(ch: Any, serial: int, hub_port: int, channel: int) -> None:
    """Which physical channel to open; must be set before `open()`. -1 is Phidget22's 'any'."""
    ch.setDeviceSerialNumber(serial)
    ch.setHubPort(hub_port)
    ch.setChannel(channel)


def common_handlers(ch: Any, q: queue.SimpleQueue[Event], which: Any) -> None:
    """Attach, detach and error handlers that only enqueue (they run on library threads)."""

    def on_attach(_ch: Any) -> None:
        q.put(("attach", which, None))

    def on_detach(_ch: Any) -> None:
        q.put(("detach", which, None))

    def on_error(_ch: Any, code: Any, description: Any) -> None:
        q.put(("error", which, (code, description)))

    ch.setOnAttachHandler(on_attach)
    ch.setOnDetachHandler(on_detach)
    ch.setOnErrorHandler(on_error)


def drain(q: queue.SimpleQueue[Event]) -> list[Event]:
    """What is queued now and nothing more: a library thread that keeps producing cannot
    hold the tick."""
    out: list[Event] = []
    for _ in range(q.qsize()):
        try:
            out.append(q.get_nowait())
        except queue.Empty:
            break
    return out


def close_quietly(ch: Any, what: str) -> None:
    if ch is None:
        return
    try:
        ch.close()
    except Exception as exc:  # noqa: BLE001 - closing must always finish
        log.debug("closing %s: %s", what, exc)


def describe(exc: BaseException) -> str:
    """A PhidgetException as text: its code and description when it has them."""
    code = getattr(exc, "code", None)
    desc = getattr(exc, "details", "") or getattr(exc, "description", "") or str(exc)
    return f"code {int(code)}: {desc}" if isinstance(code, int) else str(desc)


def clamp_interval(ch: Any, ms: int, what: str) -> int:
    """`ms` clamped to the channel's Min/MaxDataInterval (only readable once attached)."""
    lo, hi = int(ch.getMinDataInterval()), int(ch.getMaxDataInterval())
    clamped = min(max(ms, lo), hi)
    if clamped != ms:
        log.info("%s: data interval %d ms clamped to %d ms", what, ms, clamped)
    return clamped


def set_servo_range(ch: Any, neutral_us: float, us_per_deg: float, lo: float, hi: float) -> None:
    """Map an attached RCServo's positions onto pulses so that one position unit is one
    degree (`neutral_us` at 0, `us_per_deg` per degree) between `lo` and `hi` (units, lo <
    hi), and let the controller ramp its speed (velocity limit and acceleration apply)."""
    ch.setMinPulseWidth(neutral_us + us_per_deg * lo)
    ch.setMaxPulseWidth(neutral_us + us_per_deg * hi)
    ch.setMinPosition(lo)
    ch.setMaxPosition(hi)
    ch.setSpeedRampingState(True)


def send_target(ch: Any, units: float, on_done: Callable[[int], None]) -> bool:
    """Hand an RCServo its target without waiting for the USB round trip when the library
    can (`setTargetPosition_async`; `on_done(code)` then runs on a library thread: queue
    only). False: it was set synchronously and is in place now."""
    set_async = getattr(ch, "setTargetPosition_async", None)
    if set_async is None:
        ch.setTargetPosition(units)
        return False

    def done(_ch: Any, code: Any, _details: Any = "") -> None:
        on_done(int(code))

    set_async(units, done)
    return True
