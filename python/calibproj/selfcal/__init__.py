"""Self-calibration: focal lengths and lens distortion from the projection."""
