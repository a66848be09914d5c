"""RAMP: a supervisor for modular field robots, driven over MCP."""

__version__ = "0.1.0"
