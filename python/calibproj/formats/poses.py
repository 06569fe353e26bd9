"""Camera pose files: ``camera_poses.json`` (a calibration) and ``truth.json`` (a simulation).

Both write every camera as ``{"R": 3x3, "t": 3, "center": 3}``, a world-to-camera
pose (``x_cam = R @ X + t``, ``center = -R.T @ t``) in the floor frame, so one reader
serves both::

    {"schema": "calibproj.camera_poses/1", "unit": "arbitrary" | "m", "frame": "floor",
     "cameras": {name: {"R": [[...], [...], [...]], "t": [...], "center": [...]}},
     "failed": {name: reason}}

``truth.json`` (``calibproj.truth/1``, unit ``"m"``) adds per camera ``K``, ``dist``,
``resolution``, ``fps`` and ``start_offset_s``, and the plane, projector and true 3D
points (see ``calibproj.simulate.truth``); ``read_poses`` reads only the poses.
``CameraPoses`` and the reader are the C++ core's (``cpp/calibproj/formats/calibration.h``),
the reader that ``Calibration.load`` uses for ``camera_poses.json``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from calibproj import _core

POSES_KIND = "camera_poses"
TRUTH_KIND = "truth"
SCHEMA_MAJOR = 1

CameraPoses = _core.formats.CameraPoses


def pose_json(R: np.ndarray, t: np.ndarray) -> dict[str, Any]:
    """How a pose is written in files: ``R`` (row-major nested lists), ``t`` and ``center``."""
    R = np.asarray(R, dtype=float).reshape(3, 3)
    t = np.asarray(t, dtype=float).reshape(3)
    return {"R": R.tolist(), "t": t.tolist(), "center": (-R.T @ t).tolist()}


def read_poses(path: str | os.PathLike) -> CameraPoses:
    """Camera poses of a ``camera_poses.json`` or a ``truth.json``, and their unit;
    FormatError naming the file and the problem."""
    return _core.formats.read_camera_poses(Path(path))
