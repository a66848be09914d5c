"""The backend's layers, as thesis figure 4.3 draws them, top to bottom.

A request walks down and its answer comes back up as a value; nothing below calls up
(`make lint` checks the imports):

- `server` — the Server layer: TCP, framing, parsing; hands each parsed message down with a
  request context (client, time) and writes the answer back.
- `robot_distribution` — the Robot Distribution layer: the robot-wide view of a request
  (which module, is it attached, who owns control), the watchdog and the module registry.
- `module_distribution` — the Module Distribution layer: each module's table of functions
  and get rows, the one place a request is validated and `describe` comes from.
- `functional` — the Functional layer: motors, drive mixing, voltage, LEDs, the lift.

Below them sits the HAL (`ramp.hal`); the modules themselves (MARTE's Base and BLE) are in
`ramp.modules`, built on the module distribution and functional layers.
"""
