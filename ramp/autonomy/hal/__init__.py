"""The autonomy's own hardware: LIDAR, IMU and pan/tilt servos, with drivers registered by name.

These are not the backend's HAL (`ramp.hal`): the autonomy's sensors hang off the autonomy's
computer and config file (`autonomy.yaml`), so removing the autonomy removes them too.
"""
