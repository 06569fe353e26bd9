"""The result of a calibration: camera poses in the floor frame, points, per-camera metrics.

Floor frame (docs/conventions.md): z up, floor z = 0; origin at the floor projection of
the centroid of the registered camera centres; x along the floor projection of the first
registered camera's optical axis. Without a metric measurement the unit is arbitrary and
the first registered camera is at height 1.

Files (``save``/``load``): ``camera_poses.json``, ``metrics.json``, ``points.ply``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.io.jsonio import FormatError


@dataclass
class CameraMetrics:
    """Per-camera figures of a calibration (pixels are undistorted pixels)."""

    mean_px: float | None  # mean reprojection error of the inlier observations
    std_px: float | None
    observations: int  # observations of this camera in the tracks
    inliers: int  # observations kept by the outlier filter
    track2_observations: int  # inliers whose point is seen by at least two registered cameras
    view_score: int  # view score (visibility pyramid) of all its observations
    failure: str | None = None
    # 1 sigma along the worst direction, from the final bundle adjustment's covariance,
    # relative to the first camera of the registration (0 for it); None when unknown.
    rotation_sigma_deg: float | None = None
    centre_sigma: float | None = None  # in the calibration's unit
    weak: bool = False  # rotation known worse than RegistrationOptions.weak_rotation_sigma_deg


@dataclass
class Calibration:
    """Camera poses (world-to-camera, floor frame), points and metrics of a calibration."""

    poses: dict[str, tuple[np.ndarray, np.ndarray]]
    failed: dict[str, str]
    metrics: dict[str, CameraMetrics]
    points: np.ndarray  # (P, 3) floor frame
    point_ids: np.ndarray  # (P,)
    unit: str = "arbitrary"
    model: str = "coplanar"
    registration_order: list[str] = field(default_factory=list)
    floor_rms: float = 0.0  # RMS distance of the floor's points to the floor, in the output unit
    # Coplanar model: other planes the projection landed on (a table top), each
    # {"normal": [3], "offset": d, "points": n} with normal . X = d in the floor frame.
    planes: list[dict[str, Any]] = field(default_factory=list)
    # The registered cameras' joint pose covariance (``_core.uncertainty.PoseUncertainty``)
    # from the final bundle adjustment; None when not known. uncertainty.json holds it.
    uncertainty: Any = None

    @property
    def registered(self) -> list[str]:
        return list(self.poses)

    def status(self, name: str) -> str:
        """``reference`` (the first registered camera: the others' sigmas are relative to
        it), ``ok``, ``weak`` (its rotation known worse than the registration's limit) or
        ``failed``."""
        if name not in self.poses:
            return "failed"
        if self.registration_order and self.registration_order[0] == name:
            return "reference"
        metrics = self.metrics.get(name)
        return "weak" if metrics is not None and metrics.weak else "ok"

    def center(self, name: str) -> np.ndarray:
        R, t = self.poses[name]
        return -R.T @ t

    @classmethod
    def from_summary(
        cls,
        summary: dict[str, Any],
        camera_names: Sequence[str],
        point_ids: np.ndarray,
        failed: dict[str, str],
        model: str,
    ) -> Calibration:
        """Build from ``Reconstruction.summarize()`` (floor frame and metrics come from C++,
        shared with the standalone executable). ``failed`` adds cameras left out before
        registration (e.g. without intrinsics)."""
        names = list(camera_names)
        failed = dict(failed)
        poses, metrics = {}, {}
        for c, name in enumerate(names):
            if summary["registered"][c]:
                poses[name] = (np.array(summary["R"][c]), np.array(summary["t"][c]))
            elif summary["failure"][c]:
                failed[name] = summary["failure"][c]
            registered = bool(summary["registered"][c])
            metrics[name] = CameraMetrics(
                mean_px=float(summary["mean_px"][c]) if registered else None,
                std_px=float(summary["std_px"][c]) if registered else None,
                observations=int(summary["observations"][c]),
                inliers=int(summary["inliers"][c]),
                track2_observations=int(summary["track2_observations"][c]),
                view_score=int(summary["view_score"][c]),
                failure=failed.get(name),
                rotation_sigma_deg=_finite_or_none(summary["rotation_sigma_deg"][c]) if registered else None,
                centre_sigma=_finite_or_none(summary["centre_sigma"][c]) if registered else None,
                weak=bool(summary["weak"][c]) and registered,
            )
        for name, reason in failed.items():
            if name not in metrics:
                metrics[name] = CameraMetrics(None, None, 0, 0, 0, 0, reason)
        return cls(
            poses=poses,
            failed=failed,
            metrics=metrics,
            points=np.array(summary["points"]).reshape(-1, 3),
            point_ids=np.asarray(point_ids)[np.asarray(summary["point_index"], dtype=np.int64)],
            model=model,
            registration_order=[names[c] for c in summary["registration_order"]],
            floor_rms=float(summary["floor_rms"]),
            planes=_planes(summary),
            uncertainty=None if summary.get("uncertainty") is None else summary["uncertainty"].named(names),
        )

    @classmethod
    def nothing_registered(cls, failed: dict[str, str], model: str) -> Calibration:
        """The result when no camera could even enter the registration."""
        metrics = {name: CameraMetrics(None, None, 0, 0, 0, 0, reason) for name, reason in failed.items()}
        return cls({}, dict(failed), metrics, np.zeros((0, 3)), np.zeros(0, dtype=np.int64), model=model)

    def save(self, directory: str | os.PathLike) -> None:
        """Write camera_poses.json, metrics.json and points.ply into ``directory``, each
        atomically (by the C++ core, as ``calibproj-native`` writes them)."""
        from calibproj import _core

        _core.formats.write_calibration(Path(directory), self)

    @classmethod
    def load(cls, directory: str | os.PathLike) -> Calibration:
        """The calibration of a results folder, read by the C++ core (the one reader of
        ``calibproj-native`` too); FormatError naming the file and the problem."""
        from calibproj import _core

        if not Path(directory).is_dir():
            raise FormatError(f"{directory}: no such results folder")
        return cls.from_core(_core.formats.read_calibration(Path(directory)))

    @classmethod
    def from_core(cls, core: Any) -> Calibration:
        """This class from the core's ``_core.formats.Calibration``."""
        metrics = {name: CameraMetrics(
            mean_px=m.mean_px, std_px=m.std_px, observations=m.observations, inliers=m.inliers,
            track2_observations=m.track2_observations, view_score=m.view_score, failure=m.failure,
            rotation_sigma_deg=m.rotation_sigma_deg, centre_sigma=m.centre_sigma, weak=m.weak)
            for name, m in core.metrics}
        return cls(poses={pose.name: (np.array(pose.R), np.array(pose.t)) for pose in core.poses},
                   failed=dict(core.failed), metrics=metrics, points=np.array(core.points).reshape(-1, 3),
                   point_ids=np.array(core.point_ids, dtype=np.int64), unit=core.unit, model=core.model,
                   registration_order=list(core.registration_order), floor_rms=core.floor_rms,
                   planes=[{"normal": [float(v) for v in plane.normal], "offset": plane.offset,
                            "points": plane.points} for plane in core.planes],
                   uncertainty=core.uncertainty)


def _planes(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The planes of a registration summary besides the floor, with their point counts."""
    point_plane = np.asarray(summary.get("point_plane", []), dtype=np.int64)
    out = []
    for k, plane in enumerate(np.asarray(summary.get("planes", np.zeros((0, 4)))).reshape(-1, 4)):
        out.append({"normal": [float(v) for v in plane[:3]], "offset": float(plane[3]),
                    "points": int(np.sum(point_plane == k + 1))})
    return out


def _finite_or_none(value: float) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


def calibration_summary(calibration: Calibration) -> list[dict[str, Any]]:
    """One row per camera: name, status, mean/std error, inliers, view score."""
    rows = []
    for name, m in calibration.metrics.items():
        rows.append(
            {
                "camera": name,
                "registered": name in calibration.poses,
                "mean_px": m.mean_px,
                "std_px": m.std_px,
                "inliers": m.inliers,
                "observations": m.observations,
                "track2": m.track2_observations,
                "view_score": m.view_score,
                "rotation_sigma_deg": m.rotation_sigma_deg,
                "centre_sigma": m.centre_sigma,
                "weak": m.weak,
                "failure": m.failure,
            }
        )
    return rows
