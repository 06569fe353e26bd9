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
``camera_poses.json`` is written with the rest of a calibration by the C++ core
(``Calibration.save``), as ``calibproj-native`` writes it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.io.json_values import boolean, describe, number, number_array, text
from calibproj.io.jsonio import FormatError, check_schema, read_json_object

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


def read_poses(path: str | os.PathLike) -> CameraPoses:
    """Camera poses of a ``camera_poses.json`` or a ``truth.json``, and their unit."""
    path = Path(path)
    document = read_json_object(path)
    tag = document.get("schema")
    kind = TRUTH_KIND if isinstance(tag, str) and tag.startswith(f"calibproj.{TRUTH_KIND}/") else POSES_KIND
    check_schema(path, tag, kind, SCHEMA_MAJOR)
    return _poses_from_document(path, document)


def _poses_from_document(path: Path, document: dict[str, Any]) -> CameraPoses:
    try:
        return _poses_of(document, str(path))
    except ValueError as error:
        raise FormatError(f"{path}: {error}") from None


def _poses_of(document: dict[str, Any], source: str) -> CameraPoses:
    unit = document.get("unit")
    if unit not in UNITS or type(unit) is not str:
        raise ValueError(f"unit must be one of {list(UNITS)}, got {describe(unit)}")
    frame = document.get("frame", "floor")
    if frame != "floor":
        raise ValueError(f"frame must be 'floor', got {describe(frame)}")
    cameras = document.get("cameras")
    if not isinstance(cameras, dict):
        raise ValueError("cameras: expected an object {name: {R, t, center}}")
    poses = {name: _read_pose(f"cameras.{name}", entry) for name, entry in cameras.items()}
    failed = document.get("failed", {})
    if not isinstance(failed, dict):
        raise ValueError("failed: expected an object {name: reason}")
    reasons = {name: text(reason, f"failed.{name}") for name, reason in failed.items()}
    weak = frozenset(name for name, entry in cameras.items() if entry.get("weak") is True)
    return CameraPoses(poses, unit, reasons, source, weak)


def _read_pose(where: str, entry: Any) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(entry, dict) or "R" not in entry or "t" not in entry:
        raise ValueError(f"{where}: expected an object with R (3x3) and t (3)")
    R = number_array(entry["R"], f"{where}.R", (3, 3))
    t = number_array(entry["t"], f"{where}.t", (3,))
    if "center" in entry:
        number_array(entry["center"], f"{where}.center", (3,))
    if "weak" in entry:
        boolean(entry["weak"], f"{where}.weak")
    for key in ("rotation_sigma_deg", "centre_sigma"):
        if entry.get(key) is not None:
            number(entry[key], f"{where}.{key}", minimum=0.0)
    if np.abs(R @ R.T - np.eye(3)).max() > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
        raise ValueError(f"{where}: R is not a rotation matrix")
    return R, t
