"""The images a board calibration is made from: the frames of a video, or image files,
each with its sharpness, and the choice of the views that cover the image best."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

logger = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv", ".avi", ".m4v", ".mts", ".webm")


@dataclass(frozen=True, eq=False)  # numpy fields
class View:
    """One image with the board found in it.

    Attributes:
        label: the image file's name, or ``frame N`` of a video.
        object_points: the corners found, board coordinates (metres, z = 0), ``(N, 3)``.
        image_points: their image positions, pixels, ``(N, 2)``.
        sharpness: variance of the Laplacian over the board's bounding box.
    """

    label: str
    object_points: np.ndarray
    image_points: np.ndarray
    sharpness: float


def grey_images(source: str | os.PathLike, step: int = 1) -> Iterator[tuple[str, np.ndarray]]:
    """``(label, grey image)`` of every ``step``-th frame of a video, or of every image
    of a folder (sorted by name), or of one image file. FileNotFoundError / ValueError
    naming the source when it holds nothing to read."""
    import cv2

    path = Path(source)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise ValueError(f"{path}: no images ({', '.join(IMAGE_SUFFIXES)})")
        for file in files:
            # One bad image among many costs that image only, named.
            try:
                yield file.name, _read_grey(file)
            except ValueError as error:
                logger.warning("%s; skipped", error)
        return
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such video, image or folder")
    if path.suffix.lower() in IMAGE_SUFFIXES:
        yield path.name, _read_grey(path)
        return
    yield from _video_frames(path, step)


def _read_grey(path: Path) -> np.ndarray:
    """The image as grey levels; ValueError naming it when OpenCV cannot read it (not an
    image, or a header claiming more pixels than OpenCV decodes)."""
    import cv2

    try:
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    except cv2.error:
        image = None
    if image is None:
        raise ValueError(f"{path}: not an image OpenCV can read")
    return image


def _video_frames(path: Path, step: int) -> Iterator[tuple[str, np.ndarray]]:
    import cv2

    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise ValueError(f"{path}: cannot open the video")
    try:
        index, decoded = 0, 0
        while True:
            ok = capture.grab()
            if not ok:
                break
            if index % step == 0:
                ok, frame = capture.retrieve()
                if ok:
                    decoded += 1
                    yield f"frame {index}", cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
            index += 1
        if decoded == 0:
            raise ValueError(f"{path}: no frame could be decoded")
    finally:
        capture.release()


def sharpness(gray: np.ndarray, points: np.ndarray) -> float:
    """Variance of the Laplacian inside the bounding box of ``points``: low for a
    blurred (moving or defocused) view."""
    import cv2

    low = np.floor(points.min(axis=0)).astype(int).clip(0)
    high = np.ceil(points.max(axis=0)).astype(int) + 1
    patch = gray[low[1]:high[1], low[0]:high[0]]
    return float(cv2.Laplacian(patch, cv2.CV_64F).var()) if patch.size else 0.0


def select_views(views: list[View], image_size: tuple[int, int], max_views: int, min_sharpness_share: float,
                 cells: int = 8) -> tuple[list[View], dict[str, str]]:
    """At most ``max_views`` views, and why each other one is left out: the blurred ones
    first (sharpness below ``min_sharpness_share`` of the median), then greedily the view
    that adds the most image cells not yet covered by corners (``cells`` along the longer
    side), ties going to the sharper view; once every reachable cell is covered, the
    sharpest of the rest. Coverage matters because distortion is only measured where
    corners were seen."""
    if not views:
        return [], {}
    median = float(np.median([v.sharpness for v in views]))
    left_out = {v.label: f"blurred (sharpness {v.sharpness:.3g}, below {min_sharpness_share:g} x the median "
                         f"{median:.3g})" for v in views if v.sharpness < min_sharpness_share * median}
    sharp = [v for v in views if v.label not in left_out]
    width, height = image_size
    step = max(width, height) / cells
    cell_sets = [set(map(tuple, np.floor(v.image_points / step).astype(int))) for v in sharp]
    chosen: list[int] = []
    covered: set = set()
    remaining = list(range(len(sharp)))
    while remaining and len(chosen) < max_views:
        best = max(remaining, key=lambda i: (len(cell_sets[i] - covered), sharp[i].sharpness))
        covered |= cell_sets[best]
        chosen.append(best)
        remaining.remove(best)
    for i in remaining:
        left_out[sharp[i].label] = f"not needed (the {max_views} views kept, --max-views, cover the image better)"
    return [sharp[i] for i in sorted(chosen)], left_out
