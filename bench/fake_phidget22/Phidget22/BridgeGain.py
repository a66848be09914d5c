"""`Phidget22.BridgeGain` stand-in (the vendor's enum values)."""


class BridgeGain:
    BRIDGE_GAIN_1 = 1
    BRIDGE_GAIN_8 = 4
    BRIDGE_GAIN_16 = 5
    BRIDGE_GAIN_32 = 6
    BRIDGE_GAIN_64 = 7
    BRIDGE_GAIN_128 = 8
