"""Capture in the operating room: record every camera while the projector plays, then calibrate or check."""
