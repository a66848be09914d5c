"""A stand-in for libphidget22's Python package (see ../README.md)."""
