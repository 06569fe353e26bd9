"""Compare estimated camera poses with a reference (ground truth or another calibration).

The estimate is first brought into the reference frame by the similarity (Sim(3),
Umeyama) that best maps its camera centres onto the reference centres, over the
cameras present in both (but those the estimate reports as weak, while three or more
others remain); then, per camera:

- rotation error: the angle of ``R_aligned @ R_ref.T``, degrees;
- centre error: ``|| s R_a C_est + t_a - C_ref ||``, in millimetres when both sides
  are metric, and in percent of the mean distance between the reference cameras.

Results also give the root mean square of those errors over the registered cameras,
the registered cameras, and the reference cameras the estimate lacks (or lists as failed).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass

import numpy as np

from calibproj.formats.poses import CameraPoses, read_poses

logger = logging.getLogger(__name__)

MIN_ALIGNMENT_CAMERAS = 3


@dataclass(frozen=True)
class CameraError:
    """Pose error of one camera after alignment."""

    rotation_deg: float
    translation: float  # in reference units
    translation_mm: float | None
    translation_pct: float


@dataclass(frozen=True)
class Comparison:
    """Pose errors of an estimate against a reference.

    Attributes:
        rotation_rmse_deg: RMSE of the rotation errors over the registered cameras.
        translation_rmse_mm: RMSE of the centre errors in mm, ``None`` unless both sides are metric.
        translation_rmse_pct: RMSE of the centre errors in % of the mean inter-camera distance
            of the reference.
        registered: reference cameras present in the estimate, in reference order.
        missing: reference cameras absent from the estimate or failed in it.
        cameras: per registered camera, its errors.
        scale: scale of the alignment (reference units per estimate unit).
        mean_camera_distance: mean distance between the reference cameras (reference units).
    """

    rotation_rmse_deg: float
    translation_rmse_mm: float | None
    translation_rmse_pct: float
    registered: list[str]
    missing: list[str]
    cameras: dict[str, CameraError]
    scale: float
    mean_camera_distance: float

    def to_json(self) -> dict:
        """The ``compare --json`` document (keys fixed by DESIGN.md)."""
        return {
            "rotation_rmse_deg": self.rotation_rmse_deg,
            "translation_rmse_mm": self.translation_rmse_mm,
            "translation_rmse_pct": self.translation_rmse_pct,
            "registered": list(self.registered),
            "missing": list(self.missing),
            "cameras": {
                name: {
                    "rotation_deg": error.rotation_deg,
                    "translation_mm": error.translation_mm,
                    "translation_pct": error.translation_pct,
                }
                for name, error in self.cameras.items()
            },
        }


def compare(estimate: CameraPoses | str | os.PathLike, truth: CameraPoses | str | os.PathLike) -> Comparison:
    """Pose errors of ``estimate`` against ``truth`` (files or ``CameraPoses``) after Sim(3) alignment."""
    estimate = estimate if isinstance(estimate, CameraPoses) else read_poses(estimate)
    truth = truth if isinstance(truth, CameraPoses) else read_poses(truth)
    registered = [name for name in truth.names if name in estimate.poses and name not in estimate.failed]
    missing = [name for name in truth.names if name not in registered]
    unknown = [name for name in estimate.names if name not in truth.poses]
    if unknown:
        logger.warning("cameras not in the reference, ignored: %s", ", ".join(unknown))
    if len(registered) < MIN_ALIGNMENT_CAMERAS:
        raise ValueError(
            f"{estimate.source or 'estimate'}: only {len(registered)} camera(s) in common with "
            f"{truth.source or 'the reference'} ({', '.join(registered) or 'none'}); "
            f"aligning needs at least {MIN_ALIGNMENT_CAMERAS}"
        )
    # A camera the estimate reports as weak does not steer the alignment (its own large
    # error would tilt every other camera); its error is still reported.
    anchors = [name for name in registered if name not in estimate.weak]
    if len(anchors) < MIN_ALIGNMENT_CAMERAS:
        anchors = registered
    elif len(anchors) < len(registered):
        logger.info("aligned on the cameras not reported weak: %s", ", ".join(anchors))
    try:
        scale, R_align, t_align = align_centers(estimate.centers(anchors), truth.centers(anchors))
    except ValueError as error:  # e.g. centres that coincide (one camera a thousand km away)
        raise ValueError(f"{estimate.source or 'estimate'}: cannot be aligned on {truth.source or 'the reference'} "
                         f"(cameras {', '.join(anchors)}): {error}") from None
    mean_distance = mean_pairwise_distance(truth.centers(truth.names))
    to_mm = 1000.0 if (estimate.is_metric and truth.is_metric) else None
    cameras = {}
    for name in registered:
        R_est, t_est = estimate.poses[name]
        R_true, _ = truth.poses[name]
        centre = scale * R_align @ estimate.center(name) + t_align
        distance = float(np.linalg.norm(centre - truth.center(name)))
        cameras[name] = CameraError(
            rotation_deg=rotation_angle_deg(R_est @ R_align.T, R_true),
            translation=distance,
            translation_mm=None if to_mm is None else distance * to_mm,
            translation_pct=100.0 * distance / mean_distance,
        )
    rotation_rmse = _rms([error.rotation_deg for error in cameras.values()])
    translation_rmse = _rms([error.translation for error in cameras.values()])
    return Comparison(
        rotation_rmse_deg=rotation_rmse,
        translation_rmse_mm=None if to_mm is None else translation_rmse * to_mm,
        translation_rmse_pct=100.0 * translation_rmse / mean_distance,
        registered=registered,
        missing=missing,
        cameras=cameras,
        scale=scale,
        mean_camera_distance=mean_distance,
    )


def align_centers(source: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Sim(3) ``(s, R, t)`` with ``target ~= s R source + t`` (Umeyama, least squares)."""
    from calibproj._core import geometry

    similarity = geometry.estimate_similarity(np.ascontiguousarray(source), np.ascontiguousarray(target))
    return float(similarity.scale), np.array(similarity.R), np.array(similarity.t).reshape(3)


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices, degrees.

    Uses the chordal distance (``||R_a - R_b||_F = 2 sqrt(2) sin(angle / 2)``), which
    stays accurate for tiny angles where the trace formula loses all digits.
    """
    chord = np.linalg.norm(R_a - R_b) / (2.0 * np.sqrt(2.0))
    return float(np.degrees(2.0 * np.arcsin(min(chord, 1.0))))


def rotation_errors_to_reference(poses: dict[str, tuple[np.ndarray, np.ndarray]], reference: str,
                                 truth: dict[str, np.ndarray]) -> dict[str, float]:
    """Per camera of ``poses`` (name -> (R, t)) but ``reference``, the rotation error
    relative to the reference camera, degrees: the angle between the estimated and the
    true ``R @ R_reference.T``. This is the error a pose covariance whose gauge is the
    reference camera describes; ``truth`` maps names to true rotations."""
    R_reference, truth_reference = poses[reference][0], truth[reference]
    return {name: rotation_angle_deg(R @ R_reference.T, truth[name] @ truth_reference.T)
            for name, (R, _) in poses.items() if name != reference}


def mean_pairwise_distance(points: np.ndarray) -> float:
    """Mean distance over all pairs of points."""
    differences = points[:, None, :] - points[None, :, :]
    distances = np.linalg.norm(differences, axis=-1)[np.triu_indices(len(points), k=1)]
    if distances.size == 0 or distances.mean() == 0.0:
        raise ValueError("the reference needs at least two distinct camera centres")
    return float(distances.mean())


def _rms(values: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values))))
