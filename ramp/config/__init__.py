"""`ramp.yaml` -> validated, frozen configuration data (SPEC 4).

The loader only reads and checks: it builds no driver and no module (that is
`ramp.runtime.build`'s job), so `ramp check` never touches hardware.
"""

from __future__ import annotations

from ramp.config.loader import (
    BusConfig,
    Config,
    DeviceConfig,
    ModuleConfig,
    ServerConfig,
    check_config,
    load_config,
    parse_config,
    valid_host,
)

__all__ = ["BusConfig", "Config", "DeviceConfig", "ModuleConfig", "ServerConfig",
           "check_config", "load_config", "parse_config", "valid_host"]
