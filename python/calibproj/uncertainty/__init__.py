"""What a calibration's uncertainty means in 3D: triangulation error in millimetres."""
