"""Plumbing both sides of RAMP need, in one leaf below all of them.

`ramp.common` is the lowest layer of the import contract: the backend (`ramp.config`,
`ramp.runtime`, ...), the MCP clients (the autonomy, the teleop console, the shell, the state
machine) and the emulators (`firmware_like`) all import it, and it imports nothing of RAMP.
It holds what each of them once wrote for itself, so a fix lands once: `yamlload` (the one
hardened YAML reader with line marks, used by every YAML input: regular files only, a size
limit checked before reading, alias, depth, NUL and UTF-8 limits, `file:line: key` errors),
`files` (opening an input that must be a regular file without ever waiting on a FIFO, for
the YAML reader and `ramp log`), `hostport` (the one `HOST:PORT` parser, IPv6 in brackets)
`tcpclient` (the non-blocking TCP client with back-off that the autonomy's MCP link and
the Hokuyo driver share) and `phidget22` (the one adapter of the vendor's Phidget22 package:
the backend's `phidget` bus and the autonomy's IMU and gimbal). Anything
here is small, has no knowledge of a robot, and never blocks the loop that calls it.
"""
