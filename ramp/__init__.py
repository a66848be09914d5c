"""RAMP: a supervisor for modular field robots, driven over MCP."""

from ramp.common import accel as _accel

__version__ = "0.1.0"

# The simulator's hot path, compiled by `make`, when the build matches the sources.
_accel.install()
