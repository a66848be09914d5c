"""`ramp-shell`: an interactive MCP client for poking the robot (SPEC 5).

It is a client like any other: it learns what the robot offers from `describe` and imports
nothing of the backend. `cli` is the command (prompt, history, watch, hold), `complete` the
pure tab completion, `render` the tables drawn from get answers.
"""

from __future__ import annotations

from ramp.shell.cli import main

__all__ = ["main"]
