"""The teleoperation console (SPEC 7; thesis 4.3, 5.3.3): a local web page for the operator.

`ramp-teleop` serves the page on 127.0.0.1 and is the only thing that talks MCP to the robot.
Like the autonomy it is an MCP client and nothing more: it reaches the robot only through
`ramp.mcp` and never imports the backend's layers, HAL, server, supervisor or config; the
backend never imports it. Its web stack (Starlette, uvicorn, websockets) is the optional
extra `teleop`, so the robot's SBC does not need it.
"""
