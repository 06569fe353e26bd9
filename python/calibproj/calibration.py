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
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.io.jsonio import FormatError, atomic_write_text, read_json, write_json
from calibproj.io.poses import read_poses, write_camera_poses
from calibproj.synthetic import matrix_from_rotvec
from calibproj.tracks import Tracks

METRICS_KIND = "metrics"
SCHEMA_MAJOR = 1
PLY_SCHEMA = "calibproj.points/1"


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


@dataclass
class FloorFrame:
    """Similarity from the reconstruction frame to the floor frame: X_f = scale * M (X - origin)."""

    M: np.ndarray
    origin: np.ndarray
    scale: float

    def points(self, X: np.ndarray) -> np.ndarray:
        return self.scale * (np.asarray(X) - self.origin) @ self.M.T

    def pose(self, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return R @ self.M.T, self.scale * (R @ self.origin + t)


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
    floor_rms: float = 0.0  # RMS distance of the points to the floor, in the output unit

    @property
    def registered(self) -> list[str]:
        return list(self.poses)

    def center(self, name: str) -> np.ndarray:
        R, t = self.poses[name]
        return -R.T @ t

    @classmethod
    def from_reconstruction(
        cls,
        tracks: Tracks,
        all_cameras: Sequence[str],
        poses: np.ndarray,
        registered: np.ndarray,
        registration_order: list[str],
        points: np.ndarray,
        reconstructed: np.ndarray,
        plane: np.ndarray | None,
        residuals: np.ndarray,
        active: np.ndarray,
        view_scores: Sequence[int],
        failed: dict[str, str],
        model: str,
    ) -> Calibration:
        names = list(tracks.camera_names)
        rotations = {n: matrix_from_rotvec(poses[c, :3]) for c, n in enumerate(names) if registered[c]}
        translations = {n: poses[c, 3:].copy() for c, n in enumerate(names) if registered[c]}
        metrics = camera_metrics(tracks, registered, residuals, active, view_scores, failed)
        for name in all_cameras:
            if name not in metrics:
                metrics[name] = CameraMetrics(None, None, 0, 0, 0, 0, failed.get(name))
        if not rotations:
            return cls({}, failed, metrics, np.zeros((0, 3)), np.zeros(0, dtype=np.int64), model=model)
        X = points[reconstructed]
        floor_plane = plane if plane is not None else fit_plane(X)
        frame = floor_frame(rotations, translations, registration_order, floor_plane)
        X_floor = frame.points(X)
        floor_poses = {n: frame.pose(rotations[n], translations[n]) for n in rotations}
        return cls(
            poses=floor_poses,
            failed=failed,
            metrics=metrics,
            points=X_floor,
            point_ids=np.asarray(tracks.point_ids)[reconstructed],
            model=model,
            registration_order=registration_order,
            floor_rms=float(np.sqrt(np.mean(X_floor[:, 2] ** 2))) if len(X_floor) else 0.0,
        )

    def save(self, directory: str | os.PathLike) -> None:
        """Write camera_poses.json, metrics.json and points.ply into ``directory``."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        write_camera_poses(directory / "camera_poses.json", self.poses, self.unit, self.failed)
        write_json(
            directory / "metrics.json",
            METRICS_KIND,
            SCHEMA_MAJOR,
            {
                "unit": self.unit,
                "model": self.model,
                "registration_order": self.registration_order,
                "floor_rms": self.floor_rms,
                "cameras": {name: asdict(m) for name, m in self.metrics.items()},
            },
        )
        write_ply(directory / "points.ply", self.points, self.point_ids)

    @classmethod
    def load(cls, directory: str | os.PathLike) -> Calibration:
        directory = Path(directory)
        poses = read_poses(directory / "camera_poses.json")
        document = read_json(directory / "metrics.json", METRICS_KIND, SCHEMA_MAJOR)
        try:
            metrics = {name: CameraMetrics(**entry) for name, entry in document["cameras"].items()}
        except (KeyError, TypeError) as error:
            raise FormatError(f"{directory / 'metrics.json'}: bad camera metrics ({error})") from None
        points, point_ids = read_ply(directory / "points.ply")
        return cls(
            poses=poses.poses,
            failed=poses.failed,
            metrics=metrics,
            points=points,
            point_ids=point_ids,
            unit=poses.unit,
            model=str(document.get("model", "coplanar")),
            registration_order=list(document.get("registration_order", [])),
            floor_rms=float(document.get("floor_rms", 0.0)),
        )


def camera_metrics(
    tracks: Tracks,
    registered: np.ndarray,
    residuals: np.ndarray,
    active: np.ndarray,
    view_scores: Sequence[int],
    failed: dict[str, str],
) -> dict[str, CameraMetrics]:
    camera_index, point_index = tracks.camera_index, tracks.point_index
    error = np.linalg.norm(residuals, axis=1)
    used = active & np.isfinite(error)
    seen_by = np.bincount(point_index[used], minlength=tracks.num_points)
    metrics = {}
    for c, name in enumerate(tracks.camera_names):
        mine = camera_index == c
        inlier = mine & used
        errors = error[inlier]
        metrics[name] = CameraMetrics(
            mean_px=float(errors.mean()) if registered[c] and errors.size else None,
            std_px=float(errors.std()) if registered[c] and errors.size else None,
            observations=int(mine.sum()),
            inliers=int(inlier.sum()),
            track2_observations=int((inlier & (seen_by[point_index] >= 2)).sum()),
            view_score=int(view_scores[c]),
            failure=failed.get(name),
        )
    return metrics


def fit_plane(points: np.ndarray, rounds: int = 3, k: float = 3.0) -> np.ndarray:
    """Plane [n, d] (n . X = d, |n| = 1) through at least 3 points, robust to stray ones:
    least squares, then again without the points farther than ``k`` robust sigmas."""
    if len(points) < 3:
        raise ValueError(f"cannot fit the floor plane to {len(points)} points")
    inliers = np.ones(len(points), bool)
    for _ in range(rounds):
        centroid = points[inliers].mean(axis=0)
        _, _, vt = np.linalg.svd(points[inliers] - centroid, full_matrices=False)
        n = vt[-1]
        distance = np.abs((points - centroid) @ n)
        sigma = 1.4826 * np.median(distance[inliers])
        keep = distance <= max(k * sigma, 1e-12)
        if keep.sum() < 3 or np.array_equal(keep, inliers):
            break
        inliers = keep
    return np.concatenate([n, [n @ centroid]])


def floor_frame(
    rotations: dict[str, np.ndarray],
    translations: dict[str, np.ndarray],
    registration_order: list[str],
    plane: np.ndarray,
) -> FloorFrame:
    """The floor frame of docs/conventions.md for cameras above ``plane``."""
    n = plane[:3] / np.linalg.norm(plane[:3])
    d = plane[3] / np.linalg.norm(plane[:3])
    centres = {name: -rotations[name].T @ translations[name] for name in rotations}
    heights = np.array([n @ c - d for c in centres.values()])
    if np.mean(heights) < 0:  # z points towards the cameras
        n, d, heights = -n, -d, -heights
    first = next(name for name in registration_order if name in rotations)
    first_height = n @ centres[first] - d
    if first_height <= 0:
        raise ValueError(f"camera {first} is not above the floor plane")
    centroid = np.mean(list(centres.values()), axis=0)
    origin = centroid - (n @ centroid - d) * n
    axis = rotations[first].T @ np.array([0.0, 0.0, 1.0])
    x_axis = axis - (axis @ n) * n
    if np.linalg.norm(x_axis) < 1e-6:  # looking straight down: use the image x axis
        axis = rotations[first].T @ np.array([1.0, 0.0, 0.0])
        x_axis = axis - (axis @ n) * n
    x_axis /= np.linalg.norm(x_axis)
    M = np.stack([x_axis, np.cross(n, x_axis), n])
    return FloorFrame(M=M, origin=origin, scale=1.0 / first_height)


def write_ply(path: str | os.PathLike, points: np.ndarray, point_ids: np.ndarray) -> None:
    """ASCII PLY of the points with their ids, written atomically."""
    header = [
        "ply",
        "format ascii 1.0",
        f"comment schema {PLY_SCHEMA}",
        f"element vertex {len(points)}",
        "property double x",
        "property double y",
        "property double z",
        "property int id",
        "end_header",
    ]
    rows = [f"{x:.9g} {y:.9g} {z:.9g} {int(i)}" for (x, y, z), i in zip(points, point_ids)]
    atomic_write_text(path, "\n".join(header + rows) + "\n")


def read_ply(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    path = Path(path)
    if not path.is_file():
        raise FormatError(f"{path}: no such file")
    lines = path.read_text(encoding="utf-8").splitlines()
    if not lines or lines[0] != "ply" or f"comment schema {PLY_SCHEMA}" not in lines[:4]:
        raise FormatError(f"{path}: not a calibproj points file ({PLY_SCHEMA})")
    try:
        end = lines.index("end_header")
        count = int(next(line.split()[2] for line in lines[:end] if line.startswith("element vertex")))
        data = np.array([line.split() for line in lines[end + 1 : end + 1 + count]], dtype=float).reshape(-1, 4)
    except (ValueError, StopIteration) as error:
        raise FormatError(f"{path}: malformed PLY ({error})") from None
    if len(data) != count:
        raise FormatError(f"{path}: {count} vertices declared, {len(data)} found")
    return data[:, :3], data[:, 3].astype(np.int64)


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
                "failure": m.failure,
            }
        )
    return rows
