"""Metric scale from one length measured in the room."""
