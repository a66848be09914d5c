"""`ramp-fleet`: the fleet supervisor's page (SPEC 14), built from what the robots publish."""
