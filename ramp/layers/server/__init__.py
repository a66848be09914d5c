"""Server layer: MCP over non-blocking TCP, serviced by the scheduler between ticks."""

from __future__ import annotations

from ramp.layers.server.tcp import Connection, McpServer, ensure_fd_limit

__all__ = ["Connection", "McpServer", "ensure_fd_limit"]
