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
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.io.json_values import boolean, describe, integer, number, text
from calibproj.io.jsonio import FormatError, read_json
from calibproj.io.poses import read_poses

METRICS_KIND = "metrics"
# Counts beyond a double's exact integers are no count (the C++ reader's int64 holds them).
MAX_COUNT = 2 ** 53
MODELS = ("free", "coplanar")  # of the registration (calibproj.registration)
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

    @property
    def registered(self) -> list[str]:
        return list(self.poses)

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
        directory = Path(directory)
        poses = read_poses(directory / "camera_poses.json")
        path = directory / "metrics.json"
        document = read_json(path, METRICS_KIND, SCHEMA_MAJOR)
        try:
            metrics, summary = _metrics_of(document)
        except ValueError as error:
            raise FormatError(f"{path}: {error}") from None
        points, point_ids = read_ply(directory / "points.ply")
        return cls(poses=poses.poses, failed=poses.failed, metrics=metrics, points=points, point_ids=point_ids,
                   unit=poses.unit, **summary)


def _metrics_of(document: dict[str, Any]) -> tuple[dict[str, CameraMetrics], dict[str, Any]]:
    """The per-camera metrics of a ``metrics.json`` and its model, registration order
    and floor RMS; ValueError naming the entry."""
    cameras = document.get("cameras")
    if not isinstance(cameras, dict):
        raise ValueError("cameras: expected an object {name: metrics}")
    metrics = {name: _camera_metrics(f"cameras.{name}", entry) for name, entry in cameras.items()}
    model = document.get("model", "coplanar")
    if type(model) is not str or model not in MODELS:
        raise ValueError(f"model must be one of {list(MODELS)}, got {describe(model)}")
    order = document.get("registration_order", [])
    if not isinstance(order, list) or not all(type(name) is str for name in order):
        raise ValueError("registration_order: expected a list of camera names")
    floor_rms = number(document.get("floor_rms", 0.0), "floor_rms", minimum=0.0)
    planes = [_plane_entry(f"planes[{k}]", entry) for k, entry in enumerate(_list(document.get("planes", []), "planes"))]
    return metrics, {"model": model, "registration_order": order, "floor_rms": floor_rms, "planes": planes}


def _list(value: Any, where: str) -> list:
    if not isinstance(value, list):
        raise ValueError(f"{where}: expected a list")
    return value


def _plane_entry(where: str, entry: Any) -> dict[str, Any]:
    if not isinstance(entry, dict) or set(entry) != {"normal", "offset", "points"}:
        raise ValueError(f"{where}: expected an object with normal, offset and points")
    normal = [number(v, f"{where}.normal") for v in _list(entry["normal"], f"{where}.normal")]
    if len(normal) != 3:
        raise ValueError(f"{where}.normal: expected 3 numbers")
    return {"normal": normal, "offset": number(entry["offset"], f"{where}.offset"),
            "points": integer(entry["points"], f"{where}.points", minimum=0, maximum=MAX_COUNT)}


def _camera_metrics(where: str, entry: Any) -> CameraMetrics:
    if not isinstance(entry, dict):
        raise ValueError(f"{where}: expected an object of metrics")
    known = {f.name: f for f in fields(CameraMetrics)}
    unknown = sorted(set(entry) - set(known))
    missing = [name for name, f in known.items() if name not in entry and f.default is MISSING]
    if unknown or missing:
        raise ValueError(f"{where}: " + "; ".join(filter(None, [unknown and f"unknown field(s) {unknown}",
                                                                 missing and f"missing field(s) {missing}"])))
    return CameraMetrics(**{name: _metric_value(name, value, f"{where}.{name}") for name, value in entry.items()})


def _metric_value(name: str, value: Any, where: str) -> Any:
    """One checked field of ``CameraMetrics``."""
    if name in ("observations", "inliers", "track2_observations", "view_score"):
        return integer(value, where, minimum=0, maximum=MAX_COUNT)
    if name == "weak":
        return boolean(value, where)
    if value is None:
        return None
    if name == "failure":
        return text(value, where)
    return number(value, where, minimum=0.0)  # pixels and sigmas


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


def read_ply(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """The points (P, 3) and their ids (P,) of a ``points.ply`` as ``Calibration.save``
    writes it; FormatError naming the file and the problem."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(f"{path}: no such file")
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError:
        raise FormatError(f"{path}: not a calibproj points file ({PLY_SCHEMA}): not UTF-8 text") from None
    if not lines or lines[0] != "ply" or f"comment schema {PLY_SCHEMA}" not in lines[:4]:
        raise FormatError(f"{path}: not a calibproj points file ({PLY_SCHEMA})")
    try:
        end = lines.index("end_header")
        count = int(next(line.split()[2] for line in lines[:end] if line.startswith("element vertex")))
    except (ValueError, IndexError, StopIteration):
        raise FormatError(f"{path}: malformed PLY header (no 'element vertex N' before 'end_header')") from None
    rows = lines[end + 1:]
    if count < 0 or len(rows) != count:
        raise FormatError(f"{path}: {count} vertices declared, {len(rows)} found")
    try:
        data = np.array([[float(value) for value in row.split()] for row in rows], dtype=float).reshape(count, 4)
    except ValueError:
        raise FormatError(f"{path}: malformed vertex (expected 4 numbers: x y z id)") from None
    if not np.isfinite(data).all():
        raise FormatError(f"{path}: a vertex is not finite")
    ids = data[:, 3]
    if not (np.all(ids == np.round(ids)) and np.all(ids >= 0) and np.all(ids < 2 ** 53)):
        raise FormatError(f"{path}: point ids must be non-negative integers")
    if len(np.unique(ids)) != len(ids):
        raise FormatError(f"{path}: a point id appears twice")
    return data[:, :3], ids.astype(np.int64)


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
