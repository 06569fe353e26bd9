"""Intrinsics from a calibration board (chessboard or ChArUco) seen in a video or images.

``calibrate_with_board(source, "chessboard:9x6:0.025")`` gives a ``BoardCalibration``
(intrinsics with each parameter's sigma, per-view errors); ``coverage_figure`` draws
where the corners were seen and each view's error. ``calibproj intrinsics`` is the
command line.
"""

from calibproj.board.fit import BoardCalibration, BoardOptions, calibrate_with_board
from calibproj.board.spec import BoardDetector, BoardSpec

__all__ = ["BoardCalibration", "BoardDetector", "BoardOptions", "BoardSpec", "calibrate_with_board"]
