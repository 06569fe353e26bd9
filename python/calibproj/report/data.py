"""What the report shows of each camera, gathered from the calibration, tracks and intrinsics."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from calibproj.formats.calibration import Calibration, CameraMetrics
from calibproj.formats.intrinsics import Intrinsics
from calibproj.registration.reprojection import reprojection_errors
from calibproj.formats.tracks import Tracks


@dataclass(frozen=True, eq=False)  # numpy fields
class CameraView:
    """One camera as the report draws it.

    Attributes:
        name: camera name.
        intrinsics: its intrinsics, ``None`` if none were given.
        metrics: its calibration metrics, ``None`` for a camera only in the tracks.
        pose: world-to-camera ``(R, t)``, ``None`` unless registered.
        failure: why it was not registered, or ``None``.
        observed_px: image positions (distorted pixels) of all its observations, ``(M, 2)``.
        residual_at_px: image positions of its observations of reconstructed points, ``(K, 2)``.
        residuals: projected minus observed, undistorted pixels, ``(K, 2)``.
        projected_px: image positions where the calibration projects those points, ``(K, 2)``.
        observed_arrays: the projected array of each observation, ``(M,)``.
        residual_arrays: the array of each observation with a residual, ``(K,)``.
        outliers: which of the ``K`` observations the outlier filter left out: the
            largest errors, as many as the calibration counts beyond its inliers.
    """

    name: str
    intrinsics: Intrinsics | None
    metrics: CameraMetrics | None
    pose: tuple[np.ndarray, np.ndarray] | None
    failure: str | None
    observed_px: np.ndarray
    residual_at_px: np.ndarray
    residuals: np.ndarray
    projected_px: np.ndarray
    observed_arrays: np.ndarray
    residual_arrays: np.ndarray
    outliers: np.ndarray

    @property
    def registered(self) -> bool:
        return self.pose is not None

    @property
    def errors(self) -> np.ndarray:
        return np.linalg.norm(self.residuals, axis=1)

    def image_size(self) -> tuple[float, float] | None:
        if self.intrinsics is None:
            return None
        if self.intrinsics.resolution is not None:
            return float(self.intrinsics.resolution[0]), float(self.intrinsics.resolution[1])
        return 2.0 * float(self.intrinsics.K[0, 2]) + 1.0, 2.0 * float(self.intrinsics.K[1, 2]) + 1.0


def camera_views(calibration: Calibration, tracks: Tracks, intrinsics: Mapping[str, Intrinsics]) -> list[CameraView]:
    """Every camera of the calibration (and of the tracks), in the calibration's order."""
    residuals = reprojection_errors(calibration, tracks, intrinsics)
    names = list(dict.fromkeys([*calibration.metrics, *calibration.poses, *calibration.failed,
                                *tracks.camera_names]))
    views = []
    for name in names:
        camera = intrinsics.get(name)
        observed_ids, observed = (tracks.observations(name) if name in tracks.camera_names
                                  else (np.zeros(0, dtype=np.int64), np.zeros((0, 2))))
        ids, at, residual = residuals.get(name, (np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros((0, 2))))
        metrics = calibration.metrics.get(name)
        failure = calibration.failed.get(name) or (metrics.failure if metrics else None)
        if name not in calibration.poses and failure is None:
            failure = "not in the calibration"
        views.append(CameraView(
            name=name, intrinsics=camera, metrics=metrics, pose=calibration.poses.get(name), failure=failure,
            observed_px=_to_image(camera, observed), residual_at_px=_to_image(camera, at), residuals=residual,
            projected_px=_to_image(camera, at + residual), observed_arrays=_arrays(observed_ids, tracks),
            residual_arrays=_arrays(ids, tracks), outliers=_outliers(residual, metrics),
        ))
    return views


def _arrays(point_ids: np.ndarray, tracks: Tracks) -> np.ndarray:
    """The array of each MSM point id; -1 for generic point ids (no arrays)."""
    point_ids = np.asarray(point_ids, dtype=np.int64)
    if not tracks.markers_per_array:
        return np.full(len(point_ids), -1, dtype=np.int64)
    return point_ids // int(tracks.markers_per_array)


def _outliers(residuals: np.ndarray, metrics: CameraMetrics | None) -> np.ndarray:
    """The observations beyond the camera's inliers: the filter cuts each camera at
    one error threshold, so they are its largest errors."""
    errors = np.linalg.norm(residuals, axis=1)
    mask = np.zeros(len(errors), dtype=bool)
    left_out = len(errors) - (metrics.inliers if metrics is not None else len(errors))
    if left_out > 0:
        mask[np.argsort(errors)[len(errors) - left_out:]] = True
    return mask


def _to_image(intrinsics: Intrinsics | None, undistorted: np.ndarray) -> np.ndarray:
    """Where undistorted pixels lie in the recorded (distorted) image."""
    if intrinsics is None or len(undistorted) == 0:
        return np.asarray(undistorted, dtype=float).reshape(-1, 2)
    return intrinsics.distort_points(undistorted)
