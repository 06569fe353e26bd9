"""Calibration boards: what a board is and how to find its corners in an image.

Two kinds, both through OpenCV:

- ``chessboard:COLSxROWS:SQUARE`` -- a chessboard of COLS x ROWS *inner* corners and
  squares SQUARE metres wide, found with ``cv2.findChessboardCornersSB`` (sub-pixel by
  construction), or with ``findChessboardCorners`` + ``cornerSubPix`` as OpenCV's
  calibration sample does (``classic``);
- ``charuco:COLSxROWS:SQUARE:MARKER:DICT`` -- a ChArUco board of COLS x ROWS squares,
  squares SQUARE and markers MARKER metres wide, ArUco dictionary DICT (``4X4_50``,
  ...), found with ``cv2.aruco.CharucoDetector``; a partly hidden board still gives the
  corners that are seen.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# A board needs at least this many corners in a view to constrain the camera (a
# homography and its distortion): fewer, and the view is not used.
MIN_CORNERS = 8
MAX_BOARD_SIDE = 200
# OpenCV's chessboard finders need more than 2 inner corners each way.
MIN_CHESSBOARD_SIDE = 3
# A square from a tenth of a millimetre (a microscope's target) to 10 m (a wall); a
# ChArUco marker of at least 5 % of its square (smaller ones are too few pixels to
# decode wherever the square is seen).
SQUARE_RANGE_M = (1e-4, 10.0)
MIN_MARKER_SHARE = 0.05


@dataclass(frozen=True)
class BoardSpec:
    """One calibration board.

    Attributes:
        kind: ``chessboard`` or ``charuco``.
        columns, rows: inner corners (chessboard) or squares (ChArUco) along x and y.
        square_m: side of a square, metres.
        marker_m: side of a ChArUco marker, metres (0 for a chessboard).
        dictionary: ArUco dictionary of a ChArUco board (``4X4_50``, ...).
    """

    kind: str
    columns: int
    rows: int
    square_m: float
    marker_m: float = 0.0
    dictionary: str = ""

    @classmethod
    def parse(cls, text: str) -> BoardSpec:
        """``chessboard:9x6:0.025`` or ``charuco:5x7:0.04:0.03:4X4_50``; ValueError saying what is wrong."""
        parts = text.split(":")
        kind = parts[0].strip().lower()
        expected = {"chessboard": 3, "charuco": 5}
        if kind not in expected or len(parts) != expected[kind]:
            raise ValueError(f"board {text!r}: expected chessboard:COLSxROWS:SQUARE_M or "
                             "charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT (e.g. charuco:5x7:0.04:0.03:4X4_50)")
        try:
            columns, rows = (int(v) for v in parts[1].lower().split("x"))
            square = float(parts[2])
            marker = float(parts[3]) if kind == "charuco" else 0.0
        except ValueError:
            raise ValueError(f"board {text!r}: COLSxROWS must be two integers and the sizes numbers") from None
        spec = cls(kind, columns, rows, square, marker, parts[4].strip().upper() if kind == "charuco" else "")
        spec.check(text)
        return spec

    def check(self, text: str) -> None:
        least = MIN_CHESSBOARD_SIDE
        if not (least <= self.columns <= MAX_BOARD_SIDE and least <= self.rows <= MAX_BOARD_SIDE):
            raise ValueError(f"board {text!r}: columns and rows must be in [{least}, {MAX_BOARD_SIDE}]")
        low, high = SQUARE_RANGE_M
        if not (np.isfinite(self.square_m) and low <= self.square_m <= high):
            raise ValueError(f"board {text!r}: the square size must be {low:g} to {high:g} m, "
                             f"got {self.square_m:g}")
        if self.kind == "charuco":
            if not (np.isfinite(self.marker_m) and MIN_MARKER_SHARE * self.square_m <= self.marker_m < self.square_m):
                raise ValueError(f"board {text!r}: the marker must be smaller than the square and at least "
                                 f"{MIN_MARKER_SHARE:.0%} of it")
            _dictionary(self.dictionary, text)

    def __str__(self) -> str:
        if self.kind == "chessboard":
            return f"chessboard:{self.columns}x{self.rows}:{self.square_m:g}"
        return f"charuco:{self.columns}x{self.rows}:{self.square_m:g}:{self.marker_m:g}:{self.dictionary}"

    def corner_count(self) -> int:
        """Corners of the whole board."""
        if self.kind == "chessboard":
            return self.columns * self.rows
        return (self.columns - 1) * (self.rows - 1)


def _dictionary(name: str, text: str):
    import cv2

    attribute = f"DICT_{name}"
    if not hasattr(cv2.aruco, attribute):
        raise ValueError(f"board {text!r}: unknown ArUco dictionary {name!r} (4X4_50, 5X5_100, 6X6_250, ...)")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, attribute))


class BoardDetector:
    """Finds a board's corners in grey images: ``detect(image)`` gives the corners'
    board coordinates ``(N, 3)`` (metres, z = 0) and image positions ``(N, 2)``, or None.

    Args:
        spec: the board.
        classic: chessboards only: ``findChessboardCorners`` + ``cornerSubPix`` (11x11
            window), as OpenCV's calibration sample finds them, instead of
            ``findChessboardCornersSB``.
    """

    def __init__(self, spec: BoardSpec, classic: bool = False) -> None:
        import cv2

        self.spec = spec
        self.classic = classic
        if spec.kind == "chessboard":
            grid = np.mgrid[0:spec.columns, 0:spec.rows].T.reshape(-1, 2)
            self.object_points = np.column_stack([grid * spec.square_m, np.zeros(len(grid))]).astype(np.float32)
        else:
            dictionary = _dictionary(spec.dictionary, str(spec))
            self.board = cv2.aruco.CharucoBoard((spec.columns, spec.rows), spec.square_m, spec.marker_m, dictionary)
            self.detector = cv2.aruco.CharucoDetector(self.board)

    def detect(self, gray: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        if self.spec.kind == "chessboard":
            return self._chessboard(gray)
        return self._charuco(gray)

    def _chessboard(self, gray: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        import cv2

        size = (self.spec.columns, self.spec.rows)
        if self.classic:
            found, corners = cv2.findChessboardCorners(gray, size, None)
            if not found:
                return None
            criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
            corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria)
        else:
            found, corners = cv2.findChessboardCornersSB(gray, size, flags=cv2.CALIB_CB_EXHAUSTIVE)
            if not found:
                return None
        return self.object_points.copy(), corners.reshape(-1, 2).astype(np.float32)

    def _charuco(self, gray: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        corners, ids, _, _ = self.detector.detectBoard(gray)
        if ids is None or len(ids) < MIN_CORNERS:
            return None
        object_points, image_points = self.board.matchImagePoints(corners, ids)
        if object_points is None or len(object_points) < MIN_CORNERS:
            return None
        return object_points.reshape(-1, 3).astype(np.float32), image_points.reshape(-1, 2).astype(np.float32)
