"""The files of a calibration: intrinsics, tracks, calibration, results folder, exports."""
