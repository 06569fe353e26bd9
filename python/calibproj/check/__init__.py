"""Check a stored calibration with a short projection, and repair the cameras that moved."""
