"""Intrinsics from a calibration board: OpenCV's calibration on the views chosen.

``calibrate_with_board(source, board)`` reads a video (every ``step``-th frame) or
images, finds the board (``BoardDetector``), leaves out blurred views, keeps the views
that cover the image best (``select_views``) and runs ``cv2.calibrateCameraExtended``:
the camera matrix and distortion, each parameter's standard deviation, the RMS
reprojection error and each view's own RMS error.
"""

from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass, field, replace

import numpy as np

from calibproj.board.spec import MIN_CHESSBOARD_SIDE, MIN_CORNERS, BoardDetector, BoardSpec
from calibproj.board.views import View, grey_images, select_views, sharpness
from calibproj.formats.intrinsics import Intrinsics

logger = logging.getLogger(__name__)

MIN_VIEWS = 3
# The order of cv2.calibrateCameraExtended's standard deviations.
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


@dataclass
class BoardOptions:
    """Knobs of a board calibration.

    Attributes:
        step: every n-th frame of a video is looked at.
        max_views: views used at most (the ones covering the image best).
        min_sharpness_share: views sharper than this share of the median sharpness are
            kept (0 keeps all).
        classic_detector: chessboards found as OpenCV's calibration sample finds them
            (``findChessboardCorners`` + ``cornerSubPix``) instead of
            ``findChessboardCornersSB``.
        rational_model: 8 distortion coefficients (k4..k6) instead of 5, for strong
            wide-angle distortion.
        fix_k3: keep k3 at 0 (a narrow lens does not determine it).
    """

    step: int = 10
    max_views: int = 40
    min_sharpness_share: float = 0.5
    classic_detector: bool = False
    rational_model: bool = False
    fix_k3: bool = False

    def check(self) -> None:
        if self.step < 1 or self.max_views < MIN_VIEWS:
            raise ValueError(f"step must be >= 1 and max_views >= {MIN_VIEWS}")
        if not (0.0 <= self.min_sharpness_share <= 1.0):
            raise ValueError("min_sharpness_share must be in [0, 1]")


@dataclass(eq=False)  # numpy fields
class BoardCalibration:
    """The result of ``calibrate_with_board``.

    Attributes:
        intrinsics: camera matrix, distortion and resolution.
        rms_px: RMS reprojection error over every corner of the views used.
        sigmas: 1-sigma of each intrinsic (``fx``, ``fy``, ``cx``, ``cy``, ``k1``, ...).
        views: the views used; ``view_rms_px`` their RMS errors in the same order.
        seen: images looked at; ``found``: those where the board was found.
        left_out: every image looked at but not used, by label, with why.
    """

    intrinsics: Intrinsics
    rms_px: float
    sigmas: dict[str, float]
    views: list[View]
    view_rms_px: np.ndarray
    seen: int
    found: int
    board: BoardSpec
    options: BoardOptions = field(default_factory=BoardOptions)
    left_out: dict[str, str] = field(default_factory=dict)

    def summary(self) -> dict:
        """A JSON-ready summary (what ``calibproj intrinsics --json`` prints)."""
        K, dist = self.intrinsics.K, np.asarray(self.intrinsics.dist).ravel()
        return {"resolution": list(self.intrinsics.resolution), "K": K.tolist(), "dist": dist.tolist(),
                **self.measurement()}

    def measurement(self) -> dict:
        """How the intrinsics were measured, as the intrinsics file records it beside them
        (``board_calibration``): the board, each parameter's 1-sigma, every view's RMS
        error, and every image left out with why."""
        return {
            "board": str(self.board),
            "rms_px": self.rms_px,
            "sigmas": self.sigmas,
            "images": {"seen": self.seen, "board_found": self.found, "used": len(self.views)},
            "views": [{"label": v.label, "corners": len(v.image_points), "rms_px": float(e),
                       "sharpness": v.sharpness} for v, e in zip(self.views, self.view_rms_px)],
            "left_out": [{"label": label, "reason": reason} for label, reason in self.left_out.items()],
        }


def calibrate_with_board(source: str | os.PathLike, board: BoardSpec | str, name: str = "camera",
                         options: BoardOptions | None = None) -> BoardCalibration:
    """Calibrate one camera's intrinsics from a video or images of a board (module docstring).

    Raises:
        ValueError: the board is found in fewer than 3 usable views, images of
            different sizes, or a source that cannot be read (named).
    """
    board = BoardSpec.parse(board) if isinstance(board, str) else board
    options = options or BoardOptions()
    options.check()
    detector = BoardDetector(board, classic=options.classic_detector)
    found, left_out, seen, size = [], {}, 0, None
    for label, gray in grey_images(source, options.step):
        seen += 1
        if size is None:
            size = (gray.shape[1], gray.shape[0])
        elif size != (gray.shape[1], gray.shape[0]):
            raise ValueError(f"{source}: {label} is {gray.shape[1]}x{gray.shape[0]}, "
                             f"the first image {size[0]}x{size[1]}")
        corners = detector.detect(gray)
        if corners is None or len(corners[1]) < MIN_CORNERS:
            left_out[label] = ("board not found" if corners is None else
                               f"{len(corners[1])} corners found ({MIN_CORNERS} needed)")
            continue
        found.append(View(label, corners[0], corners[1], sharpness(gray, corners[1])))
    views, not_used = select_views(found, size or (1, 1), options.max_views, options.min_sharpness_share)
    left_out.update(not_used)
    logger.info("%s: board %s found in %d of %d images; %d views used", source, board, len(found), seen, len(views))
    if len(views) < MIN_VIEWS:
        raise ValueError(f"{source}: the board {board} was found in {len(found)} of {seen} images "
                         f"({len(views)} usable); at least {MIN_VIEWS} views are needed"
                         f"{_board_hint(source, board, options) if not found else ''}")
    result = _calibrate(views, size, board, name, options, seen, len(found))
    result.left_out = {label: left_out[label] for label in sorted(left_out, key=_natural_order)}
    return result


# Images tried with another reading of a board that was found nowhere.
HINT_IMAGES = 6


def _board_hint(source: str | os.PathLike, board: BoardSpec, options: BoardOptions) -> str:
    """When a chessboard is found nowhere but its squares-minus-one reading is: COLSxROWS
    counts inner corners, and the count of squares is the usual mistake."""
    if board.kind != "chessboard" or min(board.columns, board.rows) - 1 < MIN_CHESSBOARD_SIDE:
        return ""
    inner = replace(board, columns=board.columns - 1, rows=board.rows - 1)
    detector = BoardDetector(inner, classic=options.classic_detector)
    tried = found = 0
    for _, gray in grey_images(source, options.step):
        tried += 1
        found += detector.detect(gray) is not None
        if tried == HINT_IMAGES:
            break
    if not found:
        return ""
    return (f" (chessboard COLSxROWS counts inner corners, squares minus one: {inner} is found in {found} of "
            f"the first {tried} images)")


def _natural_order(label: str) -> tuple:
    """``frame 20`` before ``frame 100``."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r"(\d+)", label))


def _calibrate(views: list[View], size: tuple[int, int], board: BoardSpec, name: str, options: BoardOptions,
               seen: int, found: int) -> BoardCalibration:
    import cv2

    flags = (cv2.CALIB_RATIONAL_MODEL if options.rational_model else 0) | (cv2.CALIB_FIX_K3 if options.fix_k3 else 0)
    rms, K, dist, _, _, std_intrinsics, _, view_errors = cv2.calibrateCameraExtended(
        [v.object_points for v in views], [v.image_points for v in views], size, None, None, flags=flags)
    dist = np.asarray(dist, dtype=float).ravel()
    names = INTRINSIC_NAMES[:4 + len(dist)]
    sigmas = {n: float(s) for n, s in zip(names, np.asarray(std_intrinsics).ravel())}
    intrinsics = Intrinsics(name=name, K=np.asarray(K, dtype=float), dist=dist, resolution=size)
    return BoardCalibration(intrinsics, float(rms), sigmas, views, np.asarray(view_errors, dtype=float).ravel(),
                            seen, found, board, options)
