"""Reprojection of a calibration's points into its cameras (undistorted pixels).

What the evaluation, the report and the COLMAP export share to measure a calibration:
``project`` (pixels and depths of points in cameras), ``depths`` and
``reprojection_errors`` (a calibration's residuals on tracks, per camera).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from calibproj.formats.calibration import Calibration
from calibproj.formats.intrinsics import Intrinsics
from calibproj.formats.tracks import Tracks


def project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undistorted pixels and depths of points ``X`` (N, 3) in cameras ``K, R, t`` (N, 3, 3), (N, 3, 3), (N, 3)."""
    in_camera = np.einsum("nij,nj->ni", R, X) + t
    depth = in_camera[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        normalised = in_camera[:, :2] / depth[:, None]
    pixels = np.einsum("nij,nj->ni", K[:, :2, :2], normalised) + K[:, :2, 2]
    return pixels, depth


def depths(R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    return np.einsum("nj,nj->n", R[:, 2, :], X) + t[:, 2]


def reprojection_errors(
    calibration: Calibration, tracks: Tracks, intrinsics: Mapping[str, Intrinsics],
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Residuals of the calibration on tracks, per registered camera with intrinsics:
    ``(point_ids (M,), observed xy (M, 2), projected - observed (M, 2))`` of its
    observations of points the calibration reconstructed (in front of the camera)."""
    lookup = {int(i): row for row, i in enumerate(calibration.point_ids)}
    out = {}
    for name in calibration.poses:
        if name not in tracks.camera_names or name not in intrinsics:
            continue
        ids, xy = tracks.observations(name)
        rows = np.array([lookup.get(int(i), -1) for i in ids], dtype=np.int64)
        ids, xy, rows = ids[rows >= 0], xy[rows >= 0], rows[rows >= 0]
        R, t = calibration.poses[name]
        n = len(rows)
        projected, depth = project(np.broadcast_to(intrinsics[name].K, (n, 3, 3)), np.broadcast_to(R, (n, 3, 3)),
                                   np.broadcast_to(t, (n, 3)), calibration.points[rows])
        front = depth > 0
        out[name] = (ids[front], xy[front], projected[front] - xy[front])
    return out
