"""The fleet link (SPEC 14): a robot's agent bridging its backend (over MCP) to an MQTT broker
in VDA 5050 2.1, and the broker set-up around it. Like the autonomy, it is an MCP client and
never imports the backend's layers, HAL or server."""
