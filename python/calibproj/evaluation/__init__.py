"""How good a calibration is: poses against a reference, reprojection on independent points."""
