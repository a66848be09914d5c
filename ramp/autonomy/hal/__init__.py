"""The autonomy's own hardware: LIDAR, IMU and pan/tilt servos, with drivers registered by name.

These are not the backend's HAL (`ramp.hal`): the autonomy's sensors hang off the autonomy's
computer and config file (`autonomy.yaml`), so removing the autonomy removes them too.

`DRIVERS` is data: per kind of device, the `driver:` names `autonomy.yaml` may use and the
(module, class) that implements each, imported only when asked for, so a missing vendor
package (Phidget22) breaks only the driver that needs it.
"""

from __future__ import annotations

import importlib
from typing import Any

DRIVERS: dict[str, dict[str, tuple[str, str]]] = {
    "lidar": {
        "hokuyo": ("ramp.autonomy.hal.hokuyo", "HokuyoLidar"),
    },
    "imu": {
        "phidget": ("ramp.autonomy.hal.phidget_spatial", "PhidgetImu"),
        "sim": ("ramp.autonomy.hal.sim", "SimImu"),
    },
    "gimbal": {
        "phidget": ("ramp.autonomy.hal.phidget_servo", "PhidgetPanTilt"),
        "sim": ("ramp.autonomy.hal.sim", "SimPanTilt"),
    },
}


def driver_class(kind: str, name: str) -> Any:
    """The class registered for `kind` (`lidar`, `imu`, `gimbal`) as `name`; ValueError lists the
    valid names."""
    try:
        table = DRIVERS[kind]
    except KeyError:
        raise ValueError(
            f"unknown device kind {kind!r} (expected one of: {', '.join(sorted(DRIVERS))})"
        ) from None
    try:
        module_name, class_name = table[name]
    except KeyError:
        raise ValueError(
            f"unknown {kind} driver {name!r} (expected one of: {', '.join(sorted(table))})"
        ) from None
    return getattr(importlib.import_module(module_name), class_name)
