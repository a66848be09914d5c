"""The distribution layers: robot (watchdog, arbitration, health) and module routers."""
