"""The autonomy's functional layer for its own sensors (thesis 5.3.4, figure 5.33): AHRS,
gimbal levelling, wall-based localization, 3D scanning and obstacle detection.

Everything runs as scheduler tasks or pure functions on the injected clock; the one record
that travels between them is `records.ScanRecord`.
"""
