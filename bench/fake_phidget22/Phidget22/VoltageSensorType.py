"""`Phidget22.VoltageSensorType` stand-in."""


class VoltageSensorType:
    SENSOR_TYPE_VOLTAGE = 0
