"""Export a calibration to the formats of other tools.

The files are written by the C++ core (``cpp/calibproj/formats/export.cc``), the same
code as ``calibproj-native calibrate --export``, so both write the same bytes.

Every format holds the registered cameras only (a failed camera has no pose), with
world-to-camera poses ``x_cam = R X + t`` in the calibration's floor frame and unit
(metres after ``--scale``, arbitrary otherwise), and how well each is known where the
format has room for it: its status (``reference``: the first registered camera, which
the others' sigmas are relative to; ``ok``; ``weak``), its 1-sigma rotation (deg) and
centre (the calibration's unit).

``yaml`` -> ``calibration_opencv.yaml``
    One ``cv2.FileStorage`` file: ``schema``, ``unit``, ``frame``, ``camera_count`` and
    a sequence ``cameras`` of maps with ``name``, ``image_width``, ``image_height``,
    ``camera_matrix`` (3x3), ``distortion_coefficients`` (1xN, OpenCV order), ``R``
    (3x3), ``t`` (3x1) and ``rvec`` (3x1, Rodrigues of R). The per-camera keys are the
    ones OpenCV calibration tools write, so one entry reads like an intrinsics file;
    ``status``, ``rotation_sigma_deg``, ``centre_sigma`` and ``mean_error_px`` follow.

``colmap`` -> ``colmap/cameras.txt``, ``colmap/images.txt``, ``colmap/points3D.txt``
    COLMAP's text model. One COLMAP camera and one image per camera (image name = the
    camera name). Camera model ``PINHOLE`` without distortion, ``OPENCV`` with
    k1, k2, p1, p2 only, ``FULL_OPENCV`` when k3 or the rational terms are used (COLMAP's
    OPENCV model has no k3); thin-prism and tilt terms have no COLMAP model and are
    refused. COLMAP puts the centre of the top-left pixel at (0.5, 0.5) where OpenCV
    puts it at (0, 0), so principal points and 2D points are shifted by half a pixel.
    ``images.txt`` holds the pose as the quaternion ``QW QX QY QZ`` (w >= 0) and ``T``
    of the same world-to-camera convention; with tracks, each image lists its
    observations as distorted image points (COLMAP applies the camera model itself),
    and ``points3D.txt`` gives every point its track and its mean reprojection error
    (undistorted pixels). Point ids are the calibration's point ids. ``cameras.txt``
    has a comment line per camera with its status and sigmas (COLMAP skips comments).

``anipose`` -> ``calibration.toml``
    aniposelib's ``CameraGroup.dump`` layout, for multi-view pose triangulation: one
    table ``cam_<i>`` per camera with ``name``, ``size`` ([width, height]), ``matrix``,
    ``distortions``, ``rotation`` (Rodrigues vector) and ``translation`` (then
    ``status``, ``rotation_sigma_deg`` and ``centre_sigma``, which aniposelib passes
    over), and a
    ``metadata`` table (``adjusted``, ``error`` = mean reprojection error of the inlier
    observations in pixels, plus
    ``unit``, ``frame`` and ``source``). Triangulated points come out in the
    calibration's unit.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from calibproj import _core
from calibproj.formats.calibration import Calibration
from calibproj.formats.intrinsics import Intrinsics
from calibproj.formats.tracks import Tracks

logger = logging.getLogger(__name__)

FORMATS = tuple(_core.formats.export_formats)


def parse_formats(text: str) -> list[str]:
    """``"yaml,colmap"`` -> ``["yaml", "colmap"]``; ValueError naming an unknown format."""
    return list(_core.formats.parse_export_formats(text))


def export(
    calibration: Calibration,
    format_name: str,
    out_dir: str | os.PathLike,
    intrinsics: Mapping[str, Intrinsics],
    tracks: Tracks | None = None,
) -> list[Path]:
    """Write the calibration in ``format_name`` (``yaml``, ``colmap`` or ``anipose``) into
    ``out_dir``; returns the files written. ``tracks`` (the calibration's) give COLMAP
    its 2D points and tracks; the other formats do not use them."""
    files, warnings = _core.formats.export(calibration, format_name, Path(out_dir), dict(intrinsics), tracks)
    for warning in warnings:
        logger.warning("%s", warning)
    files = [Path(f) for f in files]
    logger.info("exported %s: %s", format_name, ", ".join(str(f) for f in files))
    return files


def export_all(calibration: Calibration, formats: Iterable[str], out_dir: str | os.PathLike,
               intrinsics: Mapping[str, Intrinsics], tracks: Tracks | None = None) -> list[Path]:
    """``export`` in every format of ``formats``."""
    return [path for f in formats for path in export(calibration, f, out_dir, intrinsics, tracks)]


def colmap_camera(intrinsics: Intrinsics) -> tuple[str, list[float]]:
    """COLMAP camera model and parameters of one camera (pixel centres shifted by 0.5)."""
    model, params = _core.formats.colmap_camera(intrinsics)
    return model, list(params)


def quaternion_wxyz(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix, with ``w >= 0``."""
    return np.asarray(_core.formats.quaternion_wxyz(np.asarray(R, dtype=float)))
