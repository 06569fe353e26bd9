"""Camera pose files: ``camera_poses.json`` (a calibration) and ``truth.json`` (a simulation).

Both write every camera as ``{"R": 3x3, "t": 3, "center": 3}``, a world-to-camera
pose (``x_cam = R @ X + t``, ``center = -R.T @ t``) in the floor frame, so one reader
serves both::

    {"schema": "calibproj.camera_poses/1", "unit": "arbitrary" | "m", "frame": "floor",
     "cameras": {name: {"R": [[...], [...], [...]], "t": [...], "center": [...]}},
     "failed": {name: reason}}

``truth.json`` (``calibproj.truth/1``, unit ``"m"``) adds per camera ``K``, ``dist``,
``resolution``, ``fps`` and ``start_offset_s``, and the plane, projector and true 3D
points (see ``calibproj.simulate.truth``); this module reads only the poses.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.io.jsonio import FormatError, check_schema, read_json_object, write_json

POSES_KIND = "camera_poses"
TRUTH_KIND = "truth"
SCHEMA_MAJOR = 1
UNITS = ("arbitrary", "m")

# A rotation read from a file may deviate this much from orthonormal (|R R^T - I|).
ROTATION_TOLERANCE = 1e-6


@dataclass(frozen=True, eq=False)  # numpy fields: compare the poses explicitly
class CameraPoses:
    """World-to-camera poses by camera name, the unit of their frame, and failed cameras.

    Attributes:
        poses: name -> ``(R (3, 3), t (3,))`` with ``x_cam = R @ X_world + t``.
        unit: ``"m"`` (metric) or ``"arbitrary"``.
        failed: name -> reason, for cameras a calibration could not register.
        source: where the poses came from (a file path), for messages.
        weak: cameras the calibration reports as weakly determined (rotation sigma above
            its limit).
    """

    poses: dict[str, tuple[np.ndarray, np.ndarray]]
    unit: str = "arbitrary"
    failed: dict[str, str] = field(default_factory=dict)
    source: str = ""
    weak: frozenset[str] = frozenset()

    @property
    def names(self) -> list[str]:
        return list(self.poses)

    @property
    def is_metric(self) -> bool:
        return self.unit == "m"

    def center(self, name: str) -> np.ndarray:
        R, t = self.poses[name]
        return -R.T @ t

    def centers(self, names: list[str]) -> np.ndarray:
        return np.array([self.center(name) for name in names]).reshape(-1, 3)


def pose_json(R: np.ndarray, t: np.ndarray) -> dict[str, Any]:
    """How a pose is written in files: ``R`` (row-major nested lists), ``t`` and ``center``."""
    R = np.asarray(R, dtype=float).reshape(3, 3)
    t = np.asarray(t, dtype=float).reshape(3)
    return {"R": R.tolist(), "t": t.tolist(), "center": (-R.T @ t).tolist()}


def write_camera_poses(
    path: str | os.PathLike,
    poses: dict[str, tuple[np.ndarray, np.ndarray]],
    unit: str,
    failed: dict[str, str] | None = None,
    uncertainty: dict[str, dict[str, Any]] | None = None,
) -> None:
    """Write ``camera_poses.json`` atomically (floor frame). ``uncertainty`` adds to a
    camera's entry its ``rotation_sigma_deg``, ``centre_sigma`` and ``weak``."""
    if unit not in UNITS:
        raise ValueError(f"unit must be one of {UNITS}, got {unit!r}")
    uncertainty = uncertainty or {}
    body = {
        "unit": unit,
        "frame": "floor",
        "cameras": {name: {**pose_json(R, t), **uncertainty.get(name, {})} for name, (R, t) in poses.items()},
        "failed": dict(failed or {}),
    }
    write_json(path, POSES_KIND, SCHEMA_MAJOR, body)


def read_poses(path: str | os.PathLike) -> CameraPoses:
    """Camera poses of a ``camera_poses.json`` or a ``truth.json``, and their unit."""
    path = Path(path)
    document = read_json_object(path)
    tag = document.get("schema")
    kind = TRUTH_KIND if isinstance(tag, str) and tag.startswith(f"calibproj.{TRUTH_KIND}/") else POSES_KIND
    check_schema(path, tag, kind, SCHEMA_MAJOR)
    return _poses_from_document(path, document)


def _poses_from_document(path: Path, document: dict[str, Any]) -> CameraPoses:
    unit = document.get("unit")
    if unit not in UNITS:
        raise FormatError(f"{path}: unit must be one of {list(UNITS)}, got {unit!r}")
    frame = document.get("frame", "floor")
    if frame != "floor":
        raise FormatError(f"{path}: frame must be 'floor', got {frame!r}")
    cameras = document.get("cameras")
    if not isinstance(cameras, dict):
        raise FormatError(f"{path}: cameras: expected an object {{name: {{R, t, center}}}}")
    poses = {name: _read_pose(path, name, entry) for name, entry in cameras.items()}
    failed = document.get("failed", {})
    if not isinstance(failed, dict):
        raise FormatError(f"{path}: failed: expected an object {{name: reason}}")
    weak = frozenset(name for name, entry in cameras.items() if isinstance(entry, dict) and entry.get("weak") is True)
    return CameraPoses(poses, unit, {str(k): str(v) for k, v in failed.items()}, str(path), weak)


def _read_pose(path: Path, name: str, entry: Any) -> tuple[np.ndarray, np.ndarray]:
    where = f"{path}: cameras.{name}"
    if not isinstance(entry, dict) or "R" not in entry or "t" not in entry:
        raise FormatError(f"{where}: expected an object with R (3x3) and t (3)")
    try:
        R = np.array(entry["R"], dtype=float)
        t = np.array(entry["t"], dtype=float)
    except (TypeError, ValueError):
        raise FormatError(f"{where}: R and t must be numbers") from None
    if R.shape != (3, 3) or t.shape != (3,):
        raise FormatError(f"{where}: R must be 3x3 and t 3 numbers, got shapes {R.shape} and {t.shape}")
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        raise FormatError(f"{where}: R and t must be finite")
    if np.abs(R @ R.T - np.eye(3)).max() > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
        raise FormatError(f"{where}: R is not a rotation matrix")
    return R, t
