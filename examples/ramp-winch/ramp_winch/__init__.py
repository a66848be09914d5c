"""ramp-winch: the example of RAMP's "Writing a module" and "Writing a driver" guides."""
