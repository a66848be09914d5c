"""ramp-arm: a 3-joint arm with a gripper as a RAMP plugin (module type `arm`)."""
