"""One exception tree for the whole supervisor.

Every error carries the MCP error code it maps to, so any layer can raise and the
distribution layers turn it into an error response without a lookup table.
"""

from __future__ import annotations


class RampError(Exception):
    """Base of every error RAMP raises on purpose."""

    code = "fault"


class ConfigError(RampError, ValueError):
    """A configuration problem, located by file, line and key path.

    The one exception for a config mistake, wherever it is found (the loader, a driver or a
    module checking the values it is built from); it is also a ValueError, since that is
    what a bad value is."""

    code = "fault"

    def __init__(self, message: str, *, file: str = "", line: int = 0, key: str = "") -> None:
        self.file = file
        self.line = line
        self.key = key
        self.detail = message
        where = file
        if file and line:
            where = f"{file}:{line}"
        parts = [p for p in (where, key) if p]
        super().__init__(": ".join([*parts, message]))


class PluginError(ConfigError):
    """A plugin named in the config whose code raised when loaded (at import). `ramp check`
    reports it as any config error; `ramp run` logs it and starts the rest of the robot,
    the module (or the bus, and the modules on it) in `fault` for good with this reason."""


class ConfigErrors(RampError):
    """Several configuration errors reported together (`ramp check` shows them all)."""

    def __init__(self, errors: list[ConfigError]) -> None:
        self.errors = errors
        super().__init__("\n".join(str(e) for e in errors))


class RequestError(RampError):
    """A request that is refused; `code` is one of the SPEC's MCP error codes."""

    def __init__(self, code: str, detail: str) -> None:
        self.code = code
        self.detail = detail
        super().__init__(f"{code}: {detail}")


class ProtocolError(RampError):
    """Bytes that are not MCP."""

    code = "syntax"


class DeviceError(RampError):
    """A device or bus failed: names both so an operator knows which cable to check."""

    code = "fault"

    def __init__(self, bus: str, message: str, device: str = "") -> None:
        self.bus = bus
        self.device = device
        self.detail = message
        who = f"bus {bus}" + (f" device {device}" if device else "")
        super().__init__(f"{who}: {message}")
