"""What the report shows of each camera, gathered from the calibration, tracks and intrinsics."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from calibproj.calibration import Calibration, CameraMetrics
from calibproj.io.intrinsics import Intrinsics
from calibproj.reprojection import reprojection_errors
from calibproj.tracks import Tracks


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
    """

    name: str
    intrinsics: Intrinsics | None
    metrics: CameraMetrics | None
    pose: tuple[np.ndarray, np.ndarray] | None
    failure: str | None
    observed_px: np.ndarray
    residual_at_px: np.ndarray
    residuals: np.ndarray

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
        observed = tracks.observations(name)[1] if name in tracks.camera_names else np.zeros((0, 2))
        _, at, residual = residuals.get(name, (None, np.zeros((0, 2)), np.zeros((0, 2))))
        metrics = calibration.metrics.get(name)
        failure = calibration.failed.get(name) or (metrics.failure if metrics else None)
        if name not in calibration.poses and failure is None:
            failure = "not in the calibration"
        views.append(CameraView(
            name=name, intrinsics=camera, metrics=metrics, pose=calibration.poses.get(name), failure=failure,
            observed_px=_to_image(camera, observed), residual_at_px=_to_image(camera, at), residuals=residual,
        ))
    return views


def _to_image(intrinsics: Intrinsics | None, undistorted: np.ndarray) -> np.ndarray:
    """Where undistorted pixels lie in the recorded (distorted) image."""
    if intrinsics is None or len(undistorted) == 0:
        return np.asarray(undistorted, dtype=float).reshape(-1, 2)
    return intrinsics.distort_points(undistorted)
