"""MCP, the MARTE Control Protocol: sans-IO codec, typed parameters and a client.

Knows nothing of the robot.
"""
