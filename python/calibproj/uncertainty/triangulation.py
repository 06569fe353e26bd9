"""How accurately the calibrated cameras place a point: the expected error of a point
triangulated from the cameras that see it, from the poses' joint covariance (the final
bundle adjustment's, cross terms included) and each camera's measured noise.

A results folder holds that covariance in ``uncertainty.json`` (written by ``calibrate``
with a map of the expected error over the working volume). Every figure is relative to
the reference camera (the first one registered): its pose and one distance (to the
floor; in the free model to the camera farthest from it) were held by the bundle
adjustment. The computation is the C++ core's
(``cpp/calibproj/uncertainty``), which writes the file.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibproj.formats.calibration import Calibration
from calibproj.formats.intrinsics import Intrinsics
from calibproj.formats.jsonio import FormatError
from calibproj.formats.results import UNCERTAINTY_FILE, load_results, resolve_intrinsics


@dataclass(frozen=True)
class PointUncertainty:
    """Per point: the covariance of its triangulation (the results' unit squared; NaN for
    a point fewer than two cameras see), its share from the poses' uncertainty (the rest
    is the new pixels' noise), and the cameras that see it."""

    covariance: np.ndarray  # (N, 3, 3)
    from_poses: np.ndarray  # (N, 3, 3)
    cameras: list[list[str]]
    unit: str

    @property
    def sigma(self) -> np.ndarray:
        """(N,) 1 sigma along each point's worst direction."""
        finite = np.isfinite(self.covariance).all(axis=(1, 2))
        out = np.full(len(self.covariance), np.nan)
        if finite.any():
            out[finite] = np.sqrt(np.clip(np.linalg.eigvalsh(self.covariance[finite])[:, -1], 0.0, None))
        return out

    @property
    def sigma_xyz(self) -> np.ndarray:
        """(N, 3) 1 sigma along the floor frame's axes."""
        return np.sqrt(np.clip(np.diagonal(self.covariance, axis1=1, axis2=2), 0.0, None))


def triangulation_uncertainty(
    results: Calibration | str | os.PathLike,
    points: np.ndarray,
    *,
    intrinsics: Mapping[str, Intrinsics] | str | os.PathLike | None = None,
    noise_px: float | None = None,
) -> PointUncertainty:
    """The expected error of the given points (N, 3) of the results' floor frame and unit,
    each triangulated from the calibrated cameras that see it (in front, inside the image).

    Args:
        results: a results folder (its ``uncertainty.json`` holds the poses' covariance) or
            a ``Calibration`` that carries one (``Calibration.uncertainty``).
        points: (N, 3) or (3,) in the floor frame, in the results' unit (metres when metric).
        intrinsics: the cameras' intrinsics; default the results folder's ``intrinsics/``.
        noise_px: the noise of the pixels the points will be triangulated from (1 sigma
            per coordinate); default each camera's own, measured on its marker centres.
    """
    from calibproj import _core

    calibration = _calibration_with_uncertainty(results)
    cameras = resolve_intrinsics(results, intrinsics)
    xyz = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if noise_px is not None and not (np.isfinite(noise_px) and noise_px > 0):
        raise ValueError(f"noise_px must be a positive number of pixels, got {noise_px}")
    covariance, from_poses, seen = _core.uncertainty.triangulation(calibration, dict(cameras), xyz,
                                                                   float(noise_px or 0.0))
    return PointUncertainty(covariance, from_poses, [list(names) for names in seen], calibration.unit)


def _calibration_with_uncertainty(results: Calibration | str | os.PathLike) -> Calibration:
    from calibproj import _core

    calibration = load_results(results)
    if calibration.uncertainty is not None:
        return calibration
    if isinstance(results, Calibration):
        raise ValueError("the calibration carries no pose covariance (Calibration.uncertainty is None)")
    path = Path(results) / UNCERTAINTY_FILE
    if not path.is_file():
        raise FormatError(f"{path}: no such file; the calibration has no pose covariance (calibrate it again "
                          "with this version of calibproj)")
    return calibration.replace(uncertainty=_core.uncertainty.read_pose_uncertainty(Path(results)))
