"""Device emulators that speak the real wire protocols, and the MARTE physics they move.

Never imported by `ramp/` except by the one simulation entry point (`ramp/simulation/backplane.py`).
"""
