"""The removable Autonomy subsystem (thesis 4.4, 5.3.4; SPEC section 6).

It is an MCP client of the backend and nothing more: it reaches the robot only through
`ramp.mcp`, and its own sensors (LIDAR, IMU, pan/tilt servos) through its own drivers in
`ramp.autonomy.hal`. It never imports the backend's layers, HAL, server or supervisor, and
nothing in the backend imports it, so deleting this package (and `ramp/statemachine/`)
leaves `ramp run`, `ramp-shell` and teleoperation untouched.

Shared infrastructure it may use: `ramp.mcp` (protocol and clients), `ramp.clock` and
`ramp.scheduler` (one loop, one injectable clock), `ramp.errors`.
"""
