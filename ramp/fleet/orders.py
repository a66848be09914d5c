"""Orders (placeholder until the autonomy's endpoint is in)."""
